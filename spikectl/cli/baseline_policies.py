"""``spikectl baselines``: the training-free controllers' table."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from spikectl.contexts import ContextSet, make_splits


@dataclass(frozen=True)
class BaselinesCommand:
    """Score do nothing, random, identify-and-plan, the oracle planner and the witness."""

    split: Literal["train", "test", "validation"] = "test"
    """Which generated set (make_splits(100, 100, seed=0, n_val=100) with the env's
    settings) to play; choose settings on train or validation, report on test."""
    contexts: Path | None = None
    """A saved ContextSet (.npz) to play instead of a generated split."""
    env: str = "spikectl/NeuronControl-v0"
    """A registered environment id: its n_neurons and extensions apply."""
    out: Path | None = None
    """Where the per-context CSV is written (default: runs/baselines/baselines.csv for the
    generated test set; for any other input a name that says which, such as
    runs/baselines/baselines-ctx.csv for --contexts ctx.npz or baselines-train.csv for
    --split train)."""
    overwrite: bool = False
    """Replace an existing CSV (otherwise refused before any work)."""
    random_seeds: int = 10
    """Seeds of the random policy (the table shows mean +- sd over them)."""
    oracle_width: int = 256
    """Beam width of the oracle planner."""
    identify_width: int = 32
    """Beam width of identify-and-plan's re-plans."""
    observation_noise_mV: float | None = None
    """Measurement noise sigma (mV) instead of the environment's."""
    hidden_fraction: float | None = None
    """Fraction of hidden neurons instead of the environment's (generated sets only)."""


ENTRY_POINT = "spikectl.envs.env:NeuronControlEnv"
BASELINES_DIR = Path("runs/baselines")


def default_out(command: BaselinesCommand) -> Path:
    """Where the CSV goes without --out: ``baselines.csv`` for the generated test set of
    the default environment, and a name carrying every other input (the contexts file,
    the split, the environment, a changed setting), so that the table of one input never
    lands on another's."""
    parts = []
    if command.contexts is not None:
        parts.append(command.contexts.stem)
    elif command.split != "test":
        parts.append(command.split)
    if command.env != BaselinesCommand.env:  # the default
        parts.append(command.env.rpartition("/")[2])
    if command.observation_noise_mV is not None:
        parts.append(f"noise{command.observation_noise_mV:g}mV")
    if command.hidden_fraction is not None:
        parts.append(f"hidden{command.hidden_fraction:g}")
    return BASELINES_DIR / "".join(["baselines", *(f"-{part}" for part in parts), ".csv"])


def check_contexts_fit(context_set, command: BaselinesCommand, extensions, n_neurons) -> None:
    """Refuse --contexts made for another environment than --env: the table would show
    their numbers under the environment's name (hidden and heterogeneous neurons, and
    the network size, belong to the contexts)."""
    wanted = extensions.context_part()
    if context_set.extensions != wanted:
        raise ValueError(
            f"--contexts {command.contexts} were made with context-level extensions "
            f"{context_set.extensions.to_dict(only_changed=True) or 'none'}, but {command.env} "
            f"has {wanted.to_dict(only_changed=True) or 'none'}: play a generated --split of "
            "it, or contexts made with its extensions (ContextSet.generate(..., extensions=...))"
        )
    if n_neurons is not None and context_set.n_neurons != n_neurons:
        raise ValueError(
            f"--contexts {command.contexts} have {context_set.n_neurons} neurons, but "
            f"{command.env} has {n_neurons}"
        )


def environment_setup(env_id: str) -> tuple[dict, Any]:
    """(the registered kwargs, the Extensions) of a spikectl environment id; refuses ids
    that are unknown or not spikectl's."""
    import gymnasium

    from spikectl.neuron.extensions import Extensions

    if env_id not in gymnasium.registry:
        raise ValueError(f"unknown environment id {env_id!r}")
    if gymnasium.spec(env_id).entry_point != ENTRY_POINT:
        raise ValueError(
            f"--env {env_id!r} is not a spikectl environment; spikectl plays "
            "spikectl/NeuronControl-v0 and its variants (spikectl/NeuronControlNoisy-v0, ...)"
        )
    kwargs = dict(gymnasium.spec(env_id).kwargs)
    return kwargs, Extensions.coerce(kwargs.get("extensions"))


def generated_split(
    split: str, n_neurons: int, extensions: Any, episode_length: int = 60, params: Any = None
) -> ContextSet:
    """The ``split`` of make_splits(100, 100, n_neurons, episode_length, seed=0, params,
    n_val=100): the sets every table of docs/baselines.md and docs/realtime.md plays
    (``params`` None: the paper's)."""
    train_set, test_set, validation_set = make_splits(
        100, 100, n_neurons, episode_length, seed=0, params=params, extensions=extensions,
        n_val=100,
    )  # fmt: skip
    return {"train": train_set, "test": test_set, "validation": validation_set}[split]


def baselines(command: BaselinesCommand) -> None:
    """Print the table of training-free controllers and write a per-context CSV."""
    from dataclasses import replace

    from spikectl.cli.output import claimed_outputs
    from spikectl.planning import Composition, IdentifyAndPlan
    from spikectl.planning.baselines import run_baselines

    for flag, value in (("--identify-width", command.identify_width),
                        ("--oracle-width", command.oracle_width)):  # fmt: skip
        if value < 1:
            raise ValueError(f"{flag} must be an integer >= 1, got {value}")
    kwargs, extensions = environment_setup(command.env)
    overrides = {
        name: value
        for name, value in (("observation_noise_mV", command.observation_noise_mV),
                            ("hidden_fraction", command.hidden_fraction))
        if value is not None
    }  # fmt: skip
    if "hidden_fraction" in overrides:
        if command.contexts is not None:
            raise ValueError("--hidden-fraction applies to generated sets, not to --contexts")
        overrides["hidden_neurons"] = 0
    extensions = replace(extensions, **overrides)
    if command.contexts is not None:
        context_set = ContextSet.load(command.contexts)
        where = str(command.contexts)
        check_contexts_fit(context_set, command, extensions, kwargs.get("n_neurons"))
    out = command.out if command.out is not None else default_out(command)
    # Claimed after the inputs are checked (their errors come first) and before the play.
    with claimed_outputs([("--out", out)], command.overwrite):
        if command.contexts is None:
            n_neurons = kwargs.get("n_neurons") or 8
            context_set = generated_split(command.split, n_neurons, extensions)
            where = f"the generated {command.split} set ({n_neurons} neurons, seed 0)"
        composition = Composition().with_width(command.identify_width)
        policy = IdentifyAndPlan(context_set.params, composition, extensions=extensions)
        results = run_baselines(context_set, extensions=extensions,
                                random_seeds=command.random_seeds,
                                oracle_width=command.oracle_width, policy=policy)  # fmt: skip
        changed = ", ".join(f"{key}={value}" for key, value in overrides.items()
                            if key != "hidden_neurons")  # fmt: skip
        print(f"{len(context_set)} contexts: {where}; environment {command.env}"
              + (f" with {changed}" if changed else ""))  # fmt: skip
        print(results.table())
        print(f"wrote {results.write_csv(out, replace=command.overwrite)}")
