"""The ``spikectl`` command line: thin wrappers, one typed config per subcommand (tyro)."""

from __future__ import annotations

import json
import os
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
import tyro

from spikectl.contexts import ContextFileError, ContextSet, make_splits


def write_json_atomic(path: Path, payload: object) -> None:
    """Write JSON so that a crash leaves either the old file or the new one, never half."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(descriptor, "w") as handle:
        json.dump(payload, handle, indent=2, default=str)
        handle.write("\n")
    os.replace(temporary, path)


@dataclass(frozen=True)
class DemoConfig:
    """Generate contexts, score the reference policies on them and save an episode raster."""

    out_dir: Path = Path("runs/demo")
    """Where the context sets, results.json and raster.png are written."""
    n_train: int = 100
    """Training contexts."""
    n_test: int = 100
    """Unseen test contexts (no topology shared with the training set)."""
    n_neurons: int = 8
    """Neurons per network."""
    episode_length: int = 60
    """Steps (ms) per episode."""
    seed: int = 0
    """Seed of the context generation and of the random policy."""


def demo(config: DemoConfig) -> dict[str, dict[str, float]]:
    """Run the demo; returns mean returns per policy and split."""
    from spikectl.experiments.figures import plot_episode_raster
    from spikectl.rollout import (
        do_nothing_policy,
        evaluate_policy,
        make_random_policy,
        make_witness_policy,
    )

    train, test = make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length, config.seed
    )
    config.out_dir.mkdir(parents=True, exist_ok=True)
    train.save(config.out_dir / "train_contexts.npz")
    test.save(config.out_dir / "test_contexts.npz")
    results: dict[str, dict[str, float]] = {}
    print(
        f"{len(train)} training and {len(test)} unseen test networks of {config.n_neurons} "
        f"neurons, episodes of {config.episode_length} steps"
    )
    print(f"{'policy':<12}{'train':>10}{'test':>10}")
    random_episodes = None
    for name in ("do-nothing", "random", "witness"):
        row = {}
        for split, contexts in (("train", train), ("test", test)):
            policy = {
                "do-nothing": do_nothing_policy,
                "random": make_random_policy(config.seed),
                "witness": make_witness_policy(contexts),
            }[name]
            episodes = evaluate_policy(contexts, policy)
            row[split] = float(episodes.returns.mean())
            if name == "random" and split == "test":
                random_episodes = episodes
        results[name] = row
        print(f"{name:<12}{row['train']:>10.3f}{row['test']:>10.3f}")
    context = test[0]
    raster = plot_episode_raster(
        context.pattern,
        random_episodes.actions[0],
        random_episodes.spikes[0],
        context.target,
        config.out_dir / "raster.png",
        title=f"random policy on unseen test network 0: return {random_episodes.returns[0]:.3f}",
    )
    write_json_atomic(
        config.out_dir / "results.json", {"config": asdict(config), "returns": results}
    )
    print(f"wrote {raster} and {config.out_dir / 'results.json'}")
    return results


@dataclass(frozen=True)
class ContextsConfig:
    """Generate a training and a test context set and save them, or describe a saved set."""

    action: Literal["generate", "show"] = "generate"
    """generate: make and save train/test sets; show: describe the file in --path."""
    out_dir: Path = Path("contexts")
    """Where generate writes train_contexts.npz and test_contexts.npz."""
    path: Path | None = None
    """The set file that show describes."""
    n_train: int = 100
    """Training contexts."""
    n_test: int = 100
    """Test contexts."""
    n_neurons: int = 8
    """Neurons per network."""
    episode_length: int = 60
    """Steps per episode."""
    seed: int = 0
    """Generation seed."""


def contexts(config: ContextsConfig) -> None:
    """Generate and save context sets, or print what a saved set holds."""
    if config.action == "show":
        if config.path is None:
            raise ValueError("show needs --path FILE")
        described = ContextSet.load(config.path)
        spikes = [int(context.pattern.sum()) for context in described]
        print(f"{config.path}: {described!r}")
        print(f"checksum {described.checksum()}")
        print(
            f"spikes per pattern: mean {np.mean(spikes):.2f}, min {min(spikes)}, max {max(spikes)}"
        )
        print(f"targets: {[context.target for context in described]}")
        return
    train, test = make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length, config.seed
    )
    for name, contexts_set in (("train", train), ("test", test)):
        path = contexts_set.save(config.out_dir / f"{name}_contexts.npz")
        print(f"wrote {path}: {contexts_set!r}")


COMMANDS = {
    "demo": (demo, DemoConfig),
    "contexts": (contexts, ContextsConfig),
}


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``spikectl`` console script."""
    choices = tuple(
        Annotated[config_type, tyro.conf.subcommand(name, description=run.__doc__)]
        for name, (run, config_type) in COMMANDS.items()
    )
    config = tyro.cli(Union[choices], args=argv, prog="spikectl")  # noqa: UP007
    run = next(run for run, config_type in COMMANDS.values() if isinstance(config, config_type))
    try:
        run(config)
    except (ValueError, TypeError, FileNotFoundError, ContextFileError) as error:
        print(f"spikectl: error: {error}", file=sys.stderr)
        raise SystemExit(2) from error


if __name__ == "__main__":
    main()
