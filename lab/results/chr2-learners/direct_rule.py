"""What a simple rule that knows the weights scores on suite v2's ``chr2`` (and, for
comparison, ``paper``): at each step, if the pattern wants a target spike LEAD steps
ahead, light (stimulate) the excitatory input of the target whose last spike lies
furthest back (a synapse releases at most every 5 steps), else do nothing. Through the
paper's current pulse LEAD = 1 (the input spikes in the step it is stimulated, the
target one step later); through ChR2, LEAD = 2 (the light drives the neuron from the
next step on). First NETWORKS networks of each task's VALIDATION set.

    python lab/results/chr2-learners/direct_rule.py [NETWORKS]
"""

from __future__ import annotations

import sys

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite

VERSION, SPLIT = 2, "validation"
REST_GAP_STEPS = 5
"""A spike at least this many steps after the last release releases (SPEC section 1)."""


class DirectRule:
    """The rule above for the networks of ``contexts`` (read by the info's context index)."""

    def __init__(self, contexts: ContextSet, lead: int) -> None:
        self.contexts, self.lead = contexts, lead
        self.last_spike: np.ndarray | None = None

    def spawn(self, index: int) -> DirectRule:
        return DirectRule(self.contexts, self.lead)

    def reset(self) -> None:
        self.last_spike = None

    def act(self, observation, info) -> int:
        step = int(observation["step"])
        context = self.contexts[int(info["context_index"])]
        voltage = np.asarray(observation["voltage"])
        if step == 0:
            self.last_spike = np.full(voltage.shape, -100)
        self.last_spike[voltage >= -50.0] = step - 1  # the spikes of the step just taken
        pattern = np.asarray(observation["pattern"])
        wanted = step + self.lead
        if wanted >= len(pattern) or not pattern[wanted]:
            return -1
        legal = np.asarray(info["action_mask"], dtype=bool)[1:]
        inputs = np.flatnonzero((np.asarray(context.weights)[:, context.target] > 0) & legal)
        if inputs.size == 0:
            return -1
        return int(inputs[np.argmin(self.last_spike[inputs])])


def main(networks: int) -> None:
    for task, lead in (("chr2", 2), ("chr2", 1), ("chr2", 3), ("paper", 1), ("paper", 2)):
        full = suite.load_split(task, SPLIT, VERSION)
        contexts = ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                              full.extensions)  # fmt: skip
        episodes = evaluate_policy(contexts, DirectRule(contexts, lead),
                                   extensions=suite.task(task, VERSION).extensions,
                                   seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
        print(f"{task}, lead {lead}: return {episodes.returns.mean():.3f} on {networks} "
              f"networks, acting on {np.mean(episodes.actions >= 0):.3f} of steps")  # fmt: skip


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
