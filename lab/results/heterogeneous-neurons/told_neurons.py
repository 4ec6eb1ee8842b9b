"""What knowing each neuron is worth on the ``heterogeneous`` validation set (a
diagnostic, never the test set): identify-and-plan told each neuron's threshold and time
constant (its spike reads and its planner use them), with its own identification and
known synapses planned at their estimated strength, and told the weights' strengths too.

    python lab/results/heterogeneous-neurons/told_neurons.py
"""

from __future__ import annotations

import copy

import numpy as np

from spikectl.experiments import suite
from spikectl.neuron.simulator import neuron_parameters
from spikectl.planning.policy import IdentifyAndPlan

TASK = "heterogeneous"


class ToldNeurons(IdentifyAndPlan):
    """Told the network's neurons (read from the set by the environment's context index);
    with ``told_weights`` also its synapses at their strengths."""

    def __init__(self, contexts, told_weights: bool, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self.told_weights = contexts, told_weights

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        if int(observation["step"]) == 0:
            self._context = self.contexts[int(info["context_index"])]
            kinds = self._context.heterogeneity
            self._neurons_told = neuron_parameters(
                self.params, kinds.thresholds_mV[None], kinds.time_constants_ms[None])
            if self.told_weights:
                self.known_weights = self._context.weights
            action = super().act(observation, info)
            self._tracker._threshold = self._neurons_told[0, 0]  # its spike reads
            return action
        return super().act(observation, info)

    def _compute_planning_weights(self):
        if self.told_weights:
            strengths = self._context.weights * self._context.heterogeneity.synaptic_scale
            return strengths.astype(np.float64), np.ones(strengths.shape, dtype=bool)
        signs, known = self.estimate.weights(self.known_sd)
        mean, _ = self.estimate.posterior()
        return np.round(mean, 2), known  # known at their strength, the others at the mean

    def _neurons(self):
        return self._neurons_told  # what the planner and its predictions simulate


def main() -> None:
    contexts = suite.load_split(TASK, "validation")
    for label, told_weights in (("told the neurons, identifying the synapses", False),
                                ("told the neurons and the synapses' strengths", True)):
        returns, cpu = suite.play(TASK, "validation", ToldNeurons(contexts, told_weights))
        print(f"{label}: {returns.mean():.3f} ({cpu:.1f} CPU s)")


if __name__ == "__main__":
    main()
