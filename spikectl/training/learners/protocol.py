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

    def __init__(self, value: float, update: int) -> None:
        super().__init__(f"the training loss became {value} at update {update}")
        self.value, self.update = value, update


class Learner(Protocol):
    """One seed's learning algorithm, driven round by round by the training loop."""

    network: torch.nn.Module
    """The acting network: greedy evaluation plays it (``step(obs, state)`` returns one
    score per action, [S, n + 1]); model.pt and best_model.pt hold its weights."""

    metric_fields: tuple[str, ...]
    """The metrics.csv columns :meth:`row_metrics` fills besides ``updates`` and ``loss``."""

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
