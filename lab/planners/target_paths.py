"""A decision part whose beam expands only the stimulations that can reach the target.

:class:`TargetPathsOnly` is identify-and-plan's decision rule with the beam's actions cut
to doing nothing and the target's ancestors in the planned network
(:func:`target_ancestors`): any other stimulation changes no planned reward, now or
later, so its children only take beam slots from states that can. It was meant to make
re-planning cheap enough for a 1 ms step at n = 16 and 32; in the suite's topologies
nearly every neuron is an ancestor of the target once a few synapses are planned, so it
saved no decision time (the measurements: lab/planners/README.md and
docs/results/realtime-iap).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.neuron import DO_NOTHING
from spikectl.planning import DecisionSettings, PlanningModel


def target_ancestors(weights: np.ndarray, target: int) -> np.ndarray:
    """bool [m]: the neurons with a path of nonzero ``weights`` [m (pre), m (post)] to
    ``target``, the target included: the only ones whose stimulation can change its
    spikes in the planned network."""
    linked = np.asarray(weights) != 0  # [pre, post]
    reaches = np.zeros(linked.shape[0], dtype=bool)
    reaches[target] = True
    frontier = reaches.copy()
    while frontier.any():  # one synapse further back each pass
        frontier = linked[:, frontier].any(axis=1) & ~reaches
        reaches |= frontier
    return reaches


@dataclass(frozen=True)
class TargetPathsOnly(DecisionSettings):
    """The core's decision rule, the beam expanding only doing nothing and the
    stimulations of :func:`target_ancestors`."""

    def planning_model(self, policy, weights: np.ndarray, situation) -> PlanningModel:
        actions = situation.actions
        reaches = target_ancestors(weights, situation.target)
        actions = actions[(actions == DO_NOTHING) | reaches[np.maximum(actions, 0)]]
        return PlanningModel(weights[None].copy(), situation.target, actions, policy.params,
                             policy.planned_neurons())  # fmt: skip
