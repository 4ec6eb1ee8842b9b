"""Loop latency (docs/extensions.md, ``latency_steps``): the actions still in flight.

With a latency of L steps an action chosen at step t stimulates at step t + L, as Cleo's
``LatencyIOProcessor`` delivers it in spikectl's Cleo bridge (``CleoSetting.latency_ms``):
nothing is stimulated in an episode's first L steps, and the actions chosen in its last
L steps never land. Rewards are unchanged: step t's reward is for step t's spikes.

So that what the agent sees stays Markov, the observation with step index s carries
``actions_in_flight``: the L actions chosen at steps s - L .. s - 1, oldest first (-1
before the episode's start), which land at steps s .. s + L - 1. With L = 0 there is no
such key and nothing here runs: the environments are the paper's.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from spikectl.neuron.simulator import DO_NOTHING

IN_FLIGHT_KEY = "actions_in_flight"
"""The observation key of the actions in flight (present only with latency)."""


class ActionDelay:
    """The actions in flight of a batch of environments: a queue of L per environment.

    ``in_flight`` int64 [B, L] holds them oldest first, in the agent's action convention
    (-1 does nothing); ``push`` queues one chosen action per environment and returns the
    ones that land now. With L = 0 ``push`` returns its input, untouched.
    """

    def __init__(self, batch: int, latency_steps: int) -> None:
        self.steps = int(latency_steps)
        self.in_flight = np.full((batch, self.steps), DO_NOTHING, dtype=np.int64)

    def push(self, chosen: np.ndarray) -> np.ndarray:
        """Queue ``chosen`` [B]; return the actions [B] chosen L steps ago, which land now."""
        if not self.steps:
            return chosen
        landing = self.in_flight[:, 0].copy()
        self.in_flight[:, :-1] = self.in_flight[:, 1:]
        self.in_flight[:, -1] = chosen
        return landing

    def push_one(self, chosen: int) -> int:
        """:meth:`push` for a batch of one, on Python ints (the single environment)."""
        if not self.steps:
            return chosen
        row = self.in_flight[0]
        landing = int(row[0])
        row[:-1] = row[1:]
        row[-1] = chosen
        return landing

    def clear(self, which: np.ndarray | slice = slice(None)) -> None:
        """Empty the queues of ``which`` environments (an episode starts: nothing in flight)."""
        self.in_flight[which] = DO_NOTHING


def in_flight_space(n_actions: int, latency_steps: int) -> spaces.MultiDiscrete:
    """The space of ``actions_in_flight``: L actions in -1..n_actions-2 (-1: nothing)."""
    return spaces.MultiDiscrete(
        np.full(latency_steps, n_actions, dtype=np.int64),
        dtype=np.int64,
        start=np.full(latency_steps, DO_NOTHING, dtype=np.int64),
    )
