"""The training loop's environments: one vector environment that collects for all K
seeds of a group at once, one evaluation environment per distinct context set, and the
baselines (doing nothing, random) a run records beside its returns.
"""

from __future__ import annotations

from spikectl.contexts import ContextSet
from spikectl.envs.controller import DoNothing, RandomLegal
from spikectl.training.config import Experiment
from spikectl.training.run_sets import baseline_episodes, make_env

SPLITS = ("train", "test", "val")


def baselines(config: Experiment, train_set: ContextSet, test_set: ContextSet) -> dict:
    """Doing nothing's and the random policy's mean returns on the training and test sets."""
    return {
        name: {
            split: float(baseline_episodes(config, contexts, policy).returns.mean())
            for split, contexts in (("train", train_set), ("test", test_set))
        }
        for name, policy in (
            ("do_nothing", DoNothing()),
            ("random", RandomLegal(config.train.seed)),
        )
    }


def collection_env(config: Experiment, train_sets: list[ContextSet], num_envs: int):
    """One vector environment of K blocks of ``num_envs`` sub-environments over the
    seeds' distinct training sets held one after another, and each seed's offset into it."""
    start: dict[str, int] = {}
    distinct: list[ContextSet] = []
    offsets = []
    for train_set in train_sets:
        key = train_set.checksum()
        if key not in start:
            start[key] = sum(len(s) for s in distinct)
            distinct.append(train_set)
        offsets.append(start[key])
    contexts = distinct[0] if len(distinct) == 1 else ContextSet(
        [context for s in distinct for context in s],
        params=distinct[0].params, extensions=distinct[0].extensions,
    )  # fmt: skip
    return make_env(config, contexts, len(train_sets) * num_envs), offsets


def evaluation_envs(config: Experiment, sets: list[tuple]) -> list[dict]:
    """Per seed, an environment for each of its sets (train, test, validation), one per
    distinct set."""
    by_checksum: dict[str, object] = {}
    per_seed = []
    for seed_sets in sets:
        envs = {}
        for split, contexts in zip(SPLITS, seed_sets, strict=True):
            if contexts is None:
                continue
            key = contexts.checksum()
            if key not in by_checksum:
                by_checksum[key] = make_env(config, contexts, len(contexts))
            envs[split] = by_checksum[key]
        per_seed.append(envs)
    return per_seed
