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
