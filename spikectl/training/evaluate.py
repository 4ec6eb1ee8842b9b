"""Batched greedy evaluation of a trained agent on context sets (its own or any other),
through the controller interface (``spikectl.load_controller``)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from spikectl.agents.greedy import GreedyController
from spikectl.contexts import ContextSet
from spikectl.envs.controller import Controller, DoNothing
from spikectl.envs.rollout import EpisodeBatch, evaluate_policy
from spikectl.training.config import Experiment
from spikectl.training.loaders import load_controller
from spikectl.training.run_files import read_config
from spikectl.training.run_sets import (
    TEST_FILE,
    TRAIN_FILE,
    VAL_FILE,
    baseline_episodes,
    check_trained_params,
)


@dataclass(frozen=True)
class SplitResult:
    """Greedy returns of an agent on one context set."""

    name: str
    returns: np.ndarray
    """[S] return per context."""
    do_nothing: float
    """Mean return of doing nothing on the same set (0.5 by construction)."""

    @property
    def mean(self) -> float:
        return float(self.returns.mean())

    @property
    def standard_error(self) -> float:
        """Standard error of the mean over contexts (the evaluation noise)."""
        if self.returns.size < 2:
            return float("nan")
        return float(self.returns.std(ddof=1) / np.sqrt(self.returns.size))


def greedy_episodes(
    network: torch.nn.Module, contexts: ContextSet, config: Experiment | None = None
) -> EpisodeBatch:
    """One greedy episode on every context of the set, in one batch; with a run's
    ``config``, in the run's environment (its params, extensions and evaluation seed,
    as its metrics.csv scored them)."""
    policy = GreedyController(network)
    if config is None:
        return evaluate_policy(contexts, policy)
    return baseline_episodes(config, contexts, policy)


def evaluate_run(
    run_dir: str | os.PathLike,
    contexts: str | os.PathLike | None = None,
    model: str = "final",
    compiled: bool = False,
    per_environment: bool = False,
) -> list[SplitResult]:
    """Greedy returns of a run's agent (``model``: "final" or "best", see
    :func:`load_agent`) on its training, test (and validation) sets, or on ``contexts``;
    ``compiled=True`` plays its compiled policy (:mod:`spikectl.agents.compiled`)
    instead of the PyTorch network, the controller a real-time rig would run;
    ``per_environment=True`` plays the network on each context alone, as the real-time
    rig does (the same actions on every CPU; metrics.csv scored one batched forward,
    which this repeats exactly on the same machine by default)."""
    run_dir = Path(run_dir)
    config = read_config(run_dir)
    if contexts is not None:
        sets = {Path(contexts).name: ContextSet.load(contexts)}
        check_trained_params(sets[Path(contexts).name], config, str(run_dir), str(contexts))
    else:
        sets = {
            "train": ContextSet.load(run_dir / TRAIN_FILE),
            "test": ContextSet.load(run_dir / TEST_FILE),
        }
        if (run_dir / VAL_FILE).exists():
            sets["validation"] = ContextSet.load(run_dir / VAL_FILE)
    controller: Controller = load_controller(
        run_dir, model=model, compiled=compiled, per_environment=per_environment
    )
    results = []
    for name, context_set in sets.items():
        if context_set.episode_length != config.env.episode_length:
            raise ValueError(
                f"{name}: episodes of {context_set.episode_length} steps; the agent was "
                f"trained on {config.env.episode_length} (its pattern encoder has that width)"
            )
        with torch_threads(config.train.torch_threads):
            episodes = baseline_episodes(config, context_set, controller)
        baseline = float(baseline_episodes(config, context_set, DoNothing()).returns.mean())
        results.append(SplitResult(name, episodes.returns, baseline))
    return results


@contextlib.contextmanager
def torch_threads(n_threads: int) -> Iterator[None]:
    """Run with the thread count the run trained with (0: Torch's default), so that a
    greedy episode sums in the same order and its return matches metrics.csv exactly."""
    before = torch.get_num_threads()
    if n_threads:
        torch.set_num_threads(n_threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)
