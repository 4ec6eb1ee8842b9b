"""The context sets of a run (training, test and validation), kept in its run directory."""

from __future__ import annotations

from pathlib import Path

from spikectl.contexts import ContextSet, make_splits
from spikectl.contexts.context_set import make_validation_set
from spikectl.training.config import TrainConfig

TRAIN_FILE = "train_contexts.npz"
TEST_FILE = "test_contexts.npz"
VAL_FILE = "val_contexts.npz"


def generated_contexts(config: TrainConfig) -> tuple[ContextSet, ContextSet]:
    """The (train, test) sets the config's sizes and ``context_seed`` generate."""
    return make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length,
        config.context_seed,
    )  # fmt: skip


def load_or_make_contexts(
    config: TrainConfig, run_dir: Path
) -> tuple[ContextSet, ContextSet, ContextSet | None]:
    """The run's (train, test, validation) sets: from the run directory when it has them
    (a resumed run), else from the config's files or generated, then saved into the run
    directory. The validation set (None when ``n_val`` is 0) is generated to share no
    topology with the training and test sets actually used."""
    paths = [run_dir / TRAIN_FILE, run_dir / TEST_FILE]
    if config.n_val:
        paths.append(run_dir / VAL_FILE)
    if all(path.exists() for path in paths):
        train, test = ContextSet.load(paths[0]), ContextSet.load(paths[1])
        validation = ContextSet.load(paths[2]) if config.n_val else None
    else:
        train, test = generated_contexts(config)
        if config.train_contexts is not None:
            train = ContextSet.load(config.train_contexts)
        if config.test_contexts is not None:
            test = ContextSet.load(config.test_contexts)
        validation = None
        if config.n_val:
            validation = make_validation_set(
                config.n_val, (train, test), config.n_neurons, config.episode_length,
                config.context_seed,
            )  # fmt: skip
        for path, contexts in zip(paths, (train, test, validation), strict=False):
            contexts.save(path)
    sets = {"training": train, "test": test, "validation": validation}
    for name, contexts in sets.items():
        if contexts is not None and (contexts.n_neurons, contexts.episode_length) != (
            config.n_neurons,
            config.episode_length,
        ):
            raise ValueError(
                f"the {name} contexts have {contexts.n_neurons} neurons and episodes of "
                f"{contexts.episode_length} steps; the config says {config.n_neurons} and "
                f"{config.episode_length}"
            )
    for first, second in (("training", "test"), ("training", "validation"), ("test", "validation")):
        if sets[first] is None or sets[second] is None:
            continue
        shared = sets[first].duplicate_topologies(sets[second])
        if shared:
            raise ValueError(
                f"{len(shared)} {second} context(s) share a topology with the {first} set "
                f"(first: {first} {shared[0][0]}, {second} {shared[0][1]}): the sets must be "
                "disjoint"
            )
    return train, test, validation
