"""Batched greedy evaluation of a trained agent on context sets (its own or any other)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from spikectl.agents import make_agent
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import EpisodeBatch, do_nothing_policy, evaluate_policy
from spikectl.training.checkpoint import checkpoint_weights
from spikectl.training.config import Experiment
from spikectl.training.contexts import TEST_FILE, TRAIN_FILE, VAL_FILE, baseline_episodes
from spikectl.training.greedy import GreedyPolicy
from spikectl.training.run_files import (
    BEST_MODEL_FILE,
    CHECKPOINT_FILE,
    MODEL_FILE,
    RunDirError,
    read_config,
)
from spikectl.training.torch_files import load_model_weights


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


MODEL_CHOICES = ("final", "best")
"""Which weights of a run to load: ``final`` (model.pt, else the last checkpoint) or
``best`` (best_model.pt, the evaluation with the highest validation return)."""


def load_agent(
    run_dir: str | os.PathLike, n_neurons: int | None = None, model: str = "final"
) -> torch.nn.Module:
    """The trained online network of a run, on CPU: ``model="final"`` loads model.pt
    (else the last checkpoint), ``model="best"`` loads best_model.pt (the network of the
    evaluation with the highest validation return).

    Both files load weights-only with their checksums verified; a damaged, foreign or
    crafted file, or weights holding NaN or infinite values, is a RunDirError.
    ``n_neurons`` builds the network for another network size (per-neuron architectures
    only; DRQN and DMDRQN refuse it when they run).
    """
    if model not in MODEL_CHOICES:
        raise ValueError(f"model must be one of {MODEL_CHOICES}, got {model!r}")
    run_dir = Path(run_dir)
    config = read_config(run_dir)
    network = make_agent(
        config.agent.arch, config.env.n_observed if n_neurons is None else n_neurons,
        config.env.episode_length, config.agent.sizes, params=config.env.params,
    )  # fmt: skip
    if model == "best":
        if not (run_dir / BEST_MODEL_FILE).exists():
            raise RunDirError(
                f"{run_dir} holds no {BEST_MODEL_FILE}: runs save one only when they have a "
                "validation set (n_val > 0), from their first evaluation on"
            )
        weights = load_model_weights(run_dir / BEST_MODEL_FILE)
    elif (run_dir / MODEL_FILE).exists():
        weights = load_model_weights(run_dir / MODEL_FILE)
    elif (run_dir / CHECKPOINT_FILE).exists():
        weights = checkpoint_weights(run_dir / CHECKPOINT_FILE)
    else:
        raise RunDirError(f"{run_dir} holds no trained weights ({MODEL_FILE} or {CHECKPOINT_FILE})")
    try:
        network.load_state_dict(weights)
    except RuntimeError as error:
        raise RunDirError(
            f"the weights in {run_dir} do not fit a {config.agent.arch} of the saved config: "
            f"{str(error).splitlines()[0]}"
        ) from error
    network.eval()
    return network


def greedy_episodes(
    network: torch.nn.Module, contexts: ContextSet, config: Experiment | None = None
) -> EpisodeBatch:
    """One greedy episode on every context of the set, in one batch; with a run's
    ``config``, in the run's environment (its params, extensions and evaluation seed,
    as its metrics.csv scored them)."""
    policy = GreedyPolicy(network)
    if config is None:
        return evaluate_policy(contexts, policy)
    return baseline_episodes(config, contexts, policy)


def evaluate_run(
    run_dir: str | os.PathLike,
    contexts: str | os.PathLike | None = None,
    model: str = "final",
) -> list[SplitResult]:
    """Greedy returns of a run's agent (``model``: "final" or "best", see
    :func:`load_agent`) on its training, test (and validation) sets, or on ``contexts``."""
    run_dir = Path(run_dir)
    config = read_config(run_dir)
    if contexts is not None:
        sets = {Path(contexts).name: ContextSet.load(contexts)}
        if sets[Path(contexts).name].params != config.env.params:
            raise ValueError(
                f"{contexts} was made with other NeuronParams than the run's environment "
                f"({run_dir / 'config.json'}): the agent would play another model"
            )
    else:
        sets = {
            "train": ContextSet.load(run_dir / TRAIN_FILE),
            "test": ContextSet.load(run_dir / TEST_FILE),
        }
        if (run_dir / VAL_FILE).exists():
            sets["validation"] = ContextSet.load(run_dir / VAL_FILE)
    network = load_agent(run_dir, model=model)
    results = []
    for name, context_set in sets.items():
        if context_set.episode_length != config.env.episode_length:
            raise ValueError(
                f"{name}: episodes of {context_set.episode_length} steps; the agent was "
                f"trained on {config.env.episode_length} (its pattern encoder has that width)"
            )
        with torch_threads(config.train.torch_threads):
            episodes = greedy_episodes(network, context_set, config)
        baseline = float(baseline_episodes(config, context_set, do_nothing_policy).returns.mean())
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
