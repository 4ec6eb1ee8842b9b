"""The named identify-and-plan played once on a suite task's set, as ``spikectl
benchmark identify-and-plan --suite 2 --task TASK`` plays it (the research record's
``play_test_row.py`` scripts of iap-chr2 and iap-rig, which write the row themselves
against the reference rows already committed)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from lab.planners.screen import timed_returns
from spikectl import NeuronControlEnv
from spikectl.experiments import suite
from spikectl.training.loaders import load_controller


def play_named(task: str, split: str = "test", version: int = 2):
    """(the suite's score, the composition's name, the number of networks): the named
    identify-and-plan on every network of ``task``'s ``split``, one seed."""
    contexts = suite.load_split(task, split, version)
    env = NeuronControlEnv(contexts=contexts, extensions=suite.task(task, version).extensions)
    played = []

    def make(seed: int):
        controller = load_controller("identify-and-plan", env=env, seed=seed)
        played.append(controller)
        return controller

    result = suite.score(task, split, make, 1, version)
    return result, played[0].composition.name, len(contexts)


def play_named_part(task: str, networks: range,
                    split: str = "test") -> tuple[np.ndarray, float, str]:  # fmt: skip
    """(returns, CPU seconds, the composition's name): the named identify-and-plan on
    ``networks`` (consecutive) of ``task``'s ``split`` (suite v2, as
    :func:`~lab.planners.screen.timed_returns` plays) with the returns :func:`play_named`
    gives them (network i is sub-environment i of the whole set's batch: its environment
    seeded ``env_seed + i``, its controller's copy ``i``), so that parts played apart (one
    a core) make up the whole row."""
    contexts = suite.load_split(task, split, 2)[networks.start : networks.stop]
    extensions = suite.task(task, 2).extensions
    env = NeuronControlEnv(contexts=contexts, extensions=extensions)
    controller = load_controller("identify-and-plan", env=env, seed=networks.start)
    returns, cpu = timed_returns(contexts, controller, extensions, first=networks.start)
    return returns, cpu, controller.composition.name


def write_rows(out: Path, task: str, row: dict, result, composition: str, version: int = 2):
    """``identify-and-plan-TASK.csv`` (``row``) and ``...-per-network.csv`` (one row per
    test network, as ``spikectl benchmark --per-network`` writes it) in ``out``."""
    with open(out / f"identify-and-plan-{task}.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(row))
        writer.writeheader()
        writer.writerow(row)
    with open(out / f"identify-and-plan-{task}-per-network.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["suite_version", "task", "split", "controller", "model", "context",
                         "return", "composition"])  # fmt: skip
        writer.writerows([version, task, "test", "identify-and-plan", "", index,
                          repr(float(value)), composition]
                         for index, value in enumerate(result.returns))  # fmt: skip
