"""Identify-and-plan's prober: what to stimulate when the plan cannot hit a wanted spike.

Early in an episode the estimate is too uncertain to plan a wanted target spike, and the
plan does nothing. A ready neuron (not refractory, vesicles back) that is stimulated
releases, and its whole row of G shows in the next step's residuals. The prober picks the
ready neuron whose outgoing weights are still unknown and that most probably excites the
target: measured on the training contexts, better than saving the likely ones for the
steps before wanted spikes (docs/baselines.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState


def ready_neurons(state: SimulatorState, params: NeuronParams) -> np.ndarray:
    """[n] neurons that release if they spike now (not refractory, vesicles back)."""
    return (state.refractory_left[0] == 0) & (
        state.steps_since_release[0] >= params.min_release_interval_steps
    )


@dataclass(frozen=True)
class ProberSettings:
    """The probing rule.

    Attributes:
        unknown_entry_bonus: added to a candidate's probability of exciting the target
            per unknown entry of its row: small, it only breaks ties, toward the row that
            teaches most.
    """

    unknown_entry_bonus: float = 1e-3

    def __post_init__(self) -> None:
        if isinstance(self.unknown_entry_bonus, bool) or not self.unknown_entry_bonus >= 0:
            raise ValueError(
                f"unknown_entry_bonus must be >= 0, got {self.unknown_entry_bonus!r}"
            )

    def choose(self, estimate, known_sd: float, known: np.ndarray, ready: np.ndarray,
               target: int, mask: np.ndarray) -> int:  # fmt: skip
        """The ready, legal neuron with unknown outgoing weights most likely to excite
        ``target`` (``estimate.excitation_probability``), or do nothing when there is
        none. ``known`` [n, n] bool, ``ready`` [n] bool, ``mask`` [n + 1] legal actions."""
        candidates = ready & ~known.all(axis=1) & mask[1:]
        if not candidates.any():
            return DO_NOTHING
        score = estimate.excitation_probability(target, known_sd)
        score = score + self.unknown_entry_bonus * (~known).sum(axis=1)
        score[~candidates] = -np.inf
        return int(np.argmax(score))
