"""Identify-and-plan under loop latency (docs/extensions.md, "Loop latency").

With a latency of L steps the action chosen at step t stimulates at step t + L. The
observation with step index s carries ``actions_in_flight``: the L actions chosen at steps
s - L .. s - 1, oldest first, which land at s .. s + L - 1 (absent when L = 0). Two facts
follow for a controller that identifies the network from what its stimulations did:

- the stimulation whose effect the observation at step s shows (the one that landed at
  step s - 1) is not ``last_action`` but the first action in flight of the observation
  before (:class:`InFlight`), so the evidence is read with it;
- an action chosen at step s meets the state after the actions in flight have landed, so
  the plan starts from that state, predicted by stepping the model through them
  (:func:`state_after`), and its first step is s + L.

The controller reads L from the observation (:func:`latency_of`), so one controller plays
every latency; with L = 0 nothing here changes what it does.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spikectl.envs.controller import ControllerInputError
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.neuron.extensions import MAX_LATENCY_STEPS
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance


def latency_of(observation: Mapping[str, Any]) -> int:
    """The loop latency L an observation shows: the length of its ``actions_in_flight``
    (0 where it has none)."""
    in_flight = observation.get(IN_FLIGHT_KEY)
    if in_flight is None:
        return 0
    shape = np.shape(in_flight)
    if len(shape) != 1 or not 1 <= shape[0] <= MAX_LATENCY_STEPS:
        raise ControllerInputError(
            f"{IN_FLIGHT_KEY} must be a vector of 1..{MAX_LATENCY_STEPS} actions, got shape {shape}"
        )
    return int(shape[0])


class InFlight:
    """One episode's actions in flight, read from its observations (agent indices,
    -1 for do nothing).

    Attributes:
        steps: the latency L.
        actions: int64 [L] the actions in flight at the last observation read, oldest
            first: the one landing now first.
    """

    def __init__(self, latency_steps: int, n_neurons: int) -> None:
        self.steps, self.n_neurons = int(latency_steps), int(n_neurons)
        self.actions = np.full(self.steps, DO_NOTHING, dtype=np.int64)

    def read(self, observation: Mapping[str, Any]) -> None:
        """Take the actions in flight of ``observation`` (at an episode's first step:
        nothing yet, all -1)."""
        if not self.steps:
            return
        if latency_of(observation) != self.steps:
            raise ControllerInputError(
                f"the loop's latency changed within the episode: {self.steps} steps at its "
                f"start, {latency_of(observation)} now"
            )
        actions = np.asarray(observation[IN_FLIGHT_KEY])
        if actions.dtype.kind not in "iu" or not (
            (actions >= DO_NOTHING) & (actions < self.n_neurons)
        ).all():  # fmt: skip
            raise ControllerInputError(
                f"{IN_FLIGHT_KEY} must hold actions in -1..{self.n_neurons - 1}, got {actions}"
            )
        self.actions = actions.astype(np.int64)

    def landed(self, observation: Mapping[str, Any]) -> int:
        """The action that stimulated at the step before ``observation`` (``last_action``
        without latency, else the first action in flight of the observation before);
        then take ``observation``'s actions in flight."""
        if not self.steps:
            return int(observation["last_action"])
        landed = int(self.actions[0])
        self.read(observation)
        return landed

    @property
    def landing_now(self) -> int | None:
        """The action that stimulates at the coming step (None without latency: the one
        chosen now)."""
        return int(self.actions[0]) if self.steps else None


def state_after(
    state: SimulatorState,
    weights: np.ndarray,
    actions: np.ndarray,
    params: NeuronParams,
    neurons: np.ndarray | None = None,
) -> SimulatorState:
    """A copy of ``state`` (a batch of one) stepped through ``actions`` [L] on ``weights``
    [m, m] (and per-neuron parameters ``neurons``, or the paper's): the state that an
    action chosen now meets when it lands. ``state`` itself is left as it was."""
    state = state.copy()
    steps, m = actions.shape[0], weights.shape[-1]
    if steps:
        advance(state, np.ascontiguousarray(weights[None]), actions[None].astype(np.int64),
                params, np.empty((1, steps, m)), np.empty((1, steps, m), dtype=bool),
                neurons)  # fmt: skip
    return state


def first_neurons(state: SimulatorState, n: int) -> SimulatorState:
    """The state of ``state``'s first ``n`` neurons (the observed ones, where the planning
    state appends virtual relay neurons)."""
    return SimulatorState(
        state.voltage_mV[:, :n], state.refractory_left[:, :n],
        state.steps_since_release[:, :n], state.released[:, :n],
    )  # fmt: skip
