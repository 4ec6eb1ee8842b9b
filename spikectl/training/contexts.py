"""The training and test context sets of a run, kept inside its run directory."""

from __future__ import annotations

from pathlib import Path

from spikectl.contexts import ContextSet, make_splits
from spikectl.training.config import TrainConfig

TRAIN_FILE = "train_contexts.npz"
TEST_FILE = "test_contexts.npz"


def generated_contexts(config: TrainConfig) -> tuple[ContextSet, ContextSet]:
    """The (train, test) sets the config's sizes and ``context_seed`` generate."""
    return make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length,
        config.context_seed,
    )  # fmt: skip


def load_or_make_contexts(config: TrainConfig, run_dir: Path) -> tuple[ContextSet, ContextSet]:
    """The run's (train, test) sets: from the run directory when it has them (a resumed
    run), else from the config's files or generated, then saved into the run directory."""
    if (run_dir / TRAIN_FILE).exists() and (run_dir / TEST_FILE).exists():
        train, test = ContextSet.load(run_dir / TRAIN_FILE), ContextSet.load(run_dir / TEST_FILE)
    else:
        train, test = generated_contexts(config)
        if config.train_contexts is not None:
            train = ContextSet.load(config.train_contexts)
        if config.test_contexts is not None:
            test = ContextSet.load(config.test_contexts)
        train.save(run_dir / TRAIN_FILE)
        test.save(run_dir / TEST_FILE)
    for name, contexts in (("training", train), ("test", test)):
        if (contexts.n_neurons, contexts.episode_length) != (
            config.n_neurons,
            config.episode_length,
        ):
            raise ValueError(
                f"the {name} contexts have {contexts.n_neurons} neurons and episodes of "
                f"{contexts.episode_length} steps; the config says {config.n_neurons} and "
                f"{config.episode_length}"
            )
    shared = train.duplicate_topologies(test)
    if shared:
        raise ValueError(
            f"{len(shared)} test context(s) share a topology with the training set "
            f"(first: train {shared[0][0]}, test {shared[0][1]}): the test set must be unseen"
        )
    return train, test
