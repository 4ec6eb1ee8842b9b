"""What the training loop (``spikectl.training.run``) asks of a learner.

One learner trains one seed. The loop owns everything around it: the run directory, the
context sets, collecting episodes through the vector environment, greedy evaluation,
metrics.csv and TensorBoard, the best model on validation, checkpoints and exact resume.
The learner owns its networks, optimiser, buffer and losses. The loop's generator (the
run's one stream of random draws: context choice, then whatever the learner draws) is
handed to the learner when it is made, so a run's draws keep one order.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np
import torch

from spikectl.envs.rollout import EpisodeBatch

Policy = Callable[[dict[str, np.ndarray], np.ndarray], np.ndarray]
"""Observations of S episodes and their action masks [S, n + 1] -> actions [S] (-1 = none)."""


class LossDiverged(ArithmeticError):
    """A learner's loss became NaN or infinite; the loop stops the run, keeping the last
    good checkpoint."""

    def __init__(self, value: float, update: int, seed: int = 0) -> None:
        super().__init__(f"the training loss became {value} at update {update}")
        self.value, self.update, self.seed = value, update, seed


class Learner(Protocol):
    """One seed's learning algorithm, driven round by round by the training loop."""

    network: torch.nn.Module
    """The acting network: greedy evaluation plays it (``step(obs, state)`` returns one
    score per action, [S, n + 1]); model.pt and best_model.pt hold its weights."""

    metric_fields: tuple[str, ...]
    """The metrics.csv columns :meth:`row_metrics` fills besides ``updates`` and ``loss``."""

    updates: int
    """Gradient updates (or whatever the learner counts as one) made so far."""

    def collection_policy(self, episode: int) -> Policy:
        """The policy that plays the next round of episodes (``episode`` done so far);
        a fresh one each round, carrying its recurrent state through the episodes."""

    def observe(self, episodes: EpisodeBatch, contexts: np.ndarray) -> None:
        """Take a finished round: the episodes and the training contexts they played."""

    def update(self, episode: int) -> None:
        """Learn after the round that started at ``episode``; raises LossDiverged."""

    def row_metrics(self, episode: int) -> dict[str, float]:
        """``updates`` (total), ``loss`` (mean since the last row, NaN if none) and the
        ``metric_fields`` for the metrics row at ``episode``; starts the means again."""

    def progress(self, episode: int) -> dict[str, str]:
        """A few short values for the progress bar (e.g. ``{"eps": "0.42"}``)."""

    def state_dict(self) -> dict[str, Any]:
        """Everything that changes, as tensors and plain data (weights-only loadable);
        the acting network's weights under ``"network"``."""

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output exactly."""


class LearnerGroup(Protocol):
    """K seeds' learners as the training loop drives them, in lockstep: one round of
    episodes for all K (played in one vector environment, seed k's ``num_envs`` episodes
    as block k), then every seed's update. ``LoopedLearners`` makes one out of K plain
    :class:`Learner` s, each bit-identical to its seed alone; a learner may also offer a
    stacked group that computes all K at once (``StackedDQN``: where that pays, a GPU)."""

    size: int
    metric_fields: tuple[str, ...]

    def collection_policy(self, episode: int) -> Policy:
        """The policy for the next round over all K blocks of sub-environments."""

    def observe(self, episodes: list[EpisodeBatch], contexts: list[np.ndarray]) -> None:
        """Take each seed's finished episodes and the indices of the training contexts
        (in its own training set) they played."""

    def update(self, episode: int) -> None:
        """Every seed's learning after the round that started at ``episode``; raises
        LossDiverged (its ``seed`` set) for the first seed whose loss diverged."""

    def network(self, seed: int) -> torch.nn.Module:
        """Seed ``seed``'s acting network as the plain module ``make_agent`` builds (what
        greedy evaluation plays and model.pt holds)."""

    def updates(self, seed: int) -> int:
        """Gradient updates seed ``seed`` has made."""

    def row_metrics(self, seed: int, episode: int) -> dict[str, float]:
        """:meth:`Learner.row_metrics` of seed ``seed``."""

    def progress(self, episode: int) -> dict[str, str]:
        """The first seed's :meth:`Learner.progress`."""

    def state_dict(self) -> dict[str, Any]:
        """Every seed's state, tensors and plain data; a looped group's is
        ``{"seeds": [learner.state_dict() for each seed]}``."""

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output exactly."""
