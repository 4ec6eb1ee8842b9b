"""Identify-and-plan that records, at chosen steps, what its estimate knows of the
network: a diagnostic of the research record. It reads the true weights from the set by
the environment's context index; the policy itself never sees them."""

from __future__ import annotations

import copy

import numpy as np

from spikectl.planning import IdentifyAndPlan


class RecordingIdentifyAndPlan(IdentifyAndPlan):
    """Appends :meth:`measure`'s row to ``record`` at each of ``checked_steps``."""

    checked_steps: tuple[int, ...] = (10, 30, 59)

    def __init__(self, contexts, record: list, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self.record = contexts, record

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)  # one record for every episode of the batch

    def act(self, observation, info) -> int:
        action = super().act(observation, info)
        step = int(observation["step"])
        if step in self.checked_steps:
            signs, known = self.estimate.weights(self.known_sd)
            truth = self.contexts[int(info["context_index"])].weights
            off_diagonal = ~np.eye(known.shape[0], dtype=bool)
            self.record.append(self.measure(step, signs, known & off_diagonal, truth))
        return action

    def measure(self, step: int, signs: np.ndarray, known: np.ndarray,
                truth: np.ndarray) -> tuple:  # fmt: skip
        """One row at ``step``: ``signs`` the estimate's weight signs, ``known`` [n, n] the
        off-diagonal entries it calls known, ``truth`` the network's weights."""
        right = (signs[known] == truth[known]).mean() if known.any() else 1.0
        return step, known.mean(), right
