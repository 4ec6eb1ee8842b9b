"""Identify-and-plan told each played network's true weights: the research record's
"told the weights" loop and the guided learner's told-weights teacher as a controller
(iap-chr2's and chr2-learners' diagnostics)."""

from __future__ import annotations

import copy

import numpy as np

from spikectl.planning import IdentifyAndPlan


class Told(IdentifyAndPlan):
    """The same loop told each network's true weights, read from ``contexts`` by the
    environment's context index at the episode's start (``info["context_index"]``)."""

    def __init__(self, contexts, **settings) -> None:
        super().__init__(**settings)
        self.contexts = contexts

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        if int(observation["step"]) == 0:
            self.told_weights = np.asarray(self.contexts[int(info["context_index"])].weights)
        return super().act(observation, info)


class ToldColumns(IdentifyAndPlan):
    """The loop whose spike likelihood starts at the true input columns of ``columns``
    (``"all"``; ``"target"``: the episode's target alone; ``"others"``: every neuron's
    but the target's), read from ``contexts`` by the environment's context index; the
    potentials are still read from spikes (:meth:`~spikectl.planning.spike_likelihood.
    SpikeLikelihoodFilter.keep_only`: the iap-rig and iap-spikes diagnostics)."""

    def __init__(self, contexts, columns: str = "all", **settings) -> None:
        if columns not in ("all", "target", "others"):
            raise ValueError(f"columns must be 'all', 'target' or 'others', got {columns!r}")
        super().__init__(**settings)
        self.contexts, self.columns = contexts, columns
        self._weights, self._target = None, None

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        if int(observation["step"]) == 0:
            self._weights = self.contexts[int(info["context_index"])].weights
            self._target = int(observation["target"])
        return super().act(observation, info)

    def _new_estimate(self, n: int):
        estimate = super()._new_estimate(n)
        told = {"all": None, "target": [self._target],
                "others": [j for j in range(n) if j != self._target]}[self.columns]
        estimate.keep_only(self._weights, told)
        return estimate
