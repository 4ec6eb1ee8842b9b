"""``spikectl demo`` and ``spikectl contexts``: context sets, made and described."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from spikectl.cli.output import refuse_existing
from spikectl.contexts import ContextSet, make_splits
from spikectl.contexts.splits import check_set_outputs, save_sets
from spikectl.files import make_dirs, write_json
from spikectl.locks import folder_lock


@dataclass(frozen=True)
class GeneratedSets:
    """The sets a command generates (``make_splits``'s arguments), shared by ``demo`` and
    ``contexts generate``."""

    n_train: int = 100
    """Training contexts."""
    n_test: int = 100
    """Unseen test contexts (no topology shared with the training set)."""
    n_neurons: int = 8
    """Neurons per network."""
    episode_length: int = 60
    """Steps (ms) per episode."""
    seed: int = 0
    """Seed of the context generation (and of demo's random policy)."""


@dataclass(frozen=True)
class DemoConfig(GeneratedSets):
    """Generate contexts, score the reference policies on them and save an episode raster."""

    out_dir: Path = Path("runs/demo")
    """Where the context sets, results.json and raster.png are written."""
    overwrite: bool = False
    """Replace the files of an earlier demo in --out-dir."""


DEMO_FILES = ("train_contexts.npz", "test_contexts.npz", "raster.png", "results.json")
"""What ``spikectl demo`` writes in --out-dir."""


def demo(config: DemoConfig) -> dict[str, dict[str, float]]:
    """A 3-second tour: score do-nothing, random and witness policies; save an episode raster."""
    if config.out_dir.exists() and not config.out_dir.is_dir():
        raise ValueError(f"--out-dir: {config.out_dir} is a file, not a folder")
    with folder_lock(config.out_dir, "writing a demo"):
        refuse_existing(config.out_dir, DEMO_FILES, config.overwrite)
        return play_demo(config)


def play_demo(config: DemoConfig) -> dict[str, dict[str, float]]:
    """Generate the sets, score the policies and write the demo's files in --out-dir."""
    from spikectl.envs.controller import DoNothing, RandomLegal, Witness
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments.figures import plot_episode_raster

    train, test = make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length, config.seed
    )
    make_dirs(config.out_dir)
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
                "do-nothing": DoNothing(),
                "random": RandomLegal(config.seed),
                "witness": Witness(contexts),
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
    write_json(config.out_dir / "results.json", {"config": asdict(config), "returns": results})
    print(f"wrote {raster} and {config.out_dir / 'results.json'}")
    return results


@dataclass(frozen=True)
class ContextsConfig(GeneratedSets):
    """Generate a training and a test context set and save them, or describe a saved set."""

    action: Literal["generate", "show"] = "generate"
    """generate: make and save train/test sets; show: describe the file in --path."""
    out_dir: Path = Path("contexts")
    """Where generate writes train_contexts.npz and test_contexts.npz."""
    path: Path | None = None
    """The set file that show describes."""
    overwrite: bool = False
    """Replace existing train_contexts.npz / test_contexts.npz in --out-dir."""


def contexts(config: ContextsConfig) -> None:
    """Generate and save context sets, or print what a saved set holds."""
    if config.action == "show":
        if config.path is None:
            raise ValueError("--path: show needs --path FILE")
        described = ContextSet.load(config.path)
        spikes = [int(context.pattern.sum()) for context in described]
        print(f"{config.path}: {described!r}")
        print(f"checksum {described.checksum()}")
        print(
            f"spikes per pattern: mean {np.mean(spikes):.2f}, min {min(spikes)}, max {max(spikes)}"
        )
        print(f"targets: {[context.target for context in described]}")
        return
    paths = {name: config.out_dir / f"{name}_contexts.npz" for name in ("train", "test")}
    if config.out_dir.exists() and not config.out_dir.is_dir():
        raise ValueError(f"--out-dir: {config.out_dir} is a file, not a folder")
    # Under the folder's lock, so that a second `spikectl contexts` at once is refused
    # instead of overwriting the first one's sets past the --overwrite guard.
    with folder_lock(config.out_dir, "writing context sets"):
        refuse_existing(config.out_dir, tuple(path.name for path in paths.values()),
                        config.overwrite)  # fmt: skip
        check_set_outputs(paths.values())  # before the sets are made
        train, test = make_splits(
            config.n_train, config.n_test, config.n_neurons, config.episode_length, config.seed
        )
        # Both checked before either is written, and renamed into place together: a
        # refused or failed write leaves no half pair (a link as the test set once left
        # a new training set beside it).
        written = save_sets({paths["train"]: train, paths["test"]: test})
        for path, contexts_set in zip(written, (train, test), strict=True):
            print(f"wrote {path}: {contexts_set!r}")
