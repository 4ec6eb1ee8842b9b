"""How much can identify-and-plan's first action gain, given what is observable at
step 0 (the target and the pattern)? Plays the planner on generator contexts (never the
suite's sets) with its first action replaced by each legal action in turn, the rest of
the episode its own, and writes every return.

    python lab/results/first-action/generate.py START COUNT OUT.csv

Context i is ``generate_context(np.random.default_rng([4344, i]), 8, 60)``; the
committed ``returns.csv`` holds contexts 0-11 999 (two processes of 6 000).
"""

from __future__ import annotations

import csv
import sys

import numpy as np

from spikectl.contexts.generation import generate_context, legal_actions
from spikectl.envs.env_support import step_rewards
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance
from spikectl.planning.policy import IdentifyAndPlan

PARAMS = NeuronParams()
CONTEXT_SEED = 4344


def context(index: int):
    return generate_context(np.random.default_rng([CONTEXT_SEED, index]), 8, 60)


def play(weights: np.ndarray, target: int, pattern: np.ndarray,
         first: int | None) -> tuple[float, int]:  # fmt: skip
    """(return, the planner's own first action) of identify-and-plan with its first
    action replaced by ``first`` (None: its own), in the paper's noise-free model."""
    n = weights.shape[0]
    policy = IdentifyAndPlan(PARAMS)
    mask = np.zeros(n + 1, dtype=np.int8)
    mask[legal_actions(n, target) + 1] = 1
    info = {"action_mask": mask}
    state = SimulatorState.at_rest(1, n, PARAMS)
    network = np.ascontiguousarray(weights[None].astype(np.int8))
    voltage, spikes = np.empty((1, 1, n)), np.empty((1, 1, n), dtype=bool)
    reward_if_spike, reward_if_silent = step_rewards(pattern)
    seen = state.voltage_mV[0].astype(np.float32)
    last, total, own = DO_NOTHING, 0.0, DO_NOTHING
    for t in range(pattern.shape[0]):
        observation = {"voltage": seen, "target": target, "pattern": pattern, "step": t,
                       "last_action": last}  # fmt: skip
        action = policy.act(observation, info)
        if t == 0:
            own = action
            if first is not None and first != action:
                # The policy predicts the next spikes from the action it takes.
                policy._predict(policy._planning_weights()[0], first)
                action = first
        advance(state, network, np.array([[action]], dtype=np.int64), PARAMS, voltage, spikes)
        total += reward_if_spike[t] if spikes[0, 0, target] else reward_if_silent[t]
        seen, last = voltage[0, 0].astype(np.float32), action
    return total, own


def main(start: int, count: int, out: str) -> None:
    with open(out, "w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["context", "target", "planner_first_action", "return_do_nothing"]
                        + [f"return_stimulate_{j}" for j in range(8)])  # fmt: skip
        for index in range(start, start + count):
            drawn = context(index)
            own_return, own = play(drawn.weights, drawn.target, drawn.pattern, None)
            returns = [""] * 9
            for action in legal_actions(8, drawn.target):
                value = own_return if action == own else play(
                    drawn.weights, drawn.target, drawn.pattern, int(action))[0]
                returns[action + 1] = f"{value:.6f}"
            writer.writerow([index, drawn.target, own, *returns])


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3])
