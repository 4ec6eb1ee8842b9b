"""The oracle planner: the best return the planner finds when it knows the weights.

It knows the context's connectivity (and heterogeneous neurons, if any) but not its
witness, and searches action sequences from rest with :func:`beam_search`. Its return
is a context's reachable return found without the witness: the headroom a
topology-agnostic controller is chasing. :class:`OraclePlanner` plays it as a
controller (``reset()`` / ``act(observation, info)``).

With loop latency (``latency_steps`` L, docs/extensions.md) an action lands L steps after
it is chosen, so the oracle plans the stimulations that land: it simulates the network
through the first L steps, in which nothing lands, searches the landing actions of steps
L .. N - 1 from the state they meet, and chooses at step t the action that lands at
t + L.

With the ChR2 actuator (``light_mW_per_mm2``, docs/extensions.md) a light pulse opens
channels that drive its neuron from the next step on for ~10 ms, so the oracle plans with
the opsins' occupancies as part of the simulated state
(:func:`~spikectl.planning.lit_search.lit_beam_search`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from spikectl.contexts import Context
from spikectl.contexts.generation import legal_actions
from spikectl.envs.controller import check_controller_input
from spikectl.envs.env_support import step_rewards
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.neuron.extensions import MAX_LATENCY_STEPS
from spikectl.neuron.opsin import OpsinActuator
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import (
    DO_NOTHING,
    SimulatorState,
    advance,
    neuron_parameters,
    simulate,
)
from spikectl.planning.beam import PlanningModel, beam_search
from spikectl.planning.lit_search import Occupancies, lit_beam_search, lit_spikes

DEFAULT_ORACLE_WIDTH = 256
"""Beam width of :func:`plan_episode`: the narrowest width whose plans score as well as
any wider one on the training networks at n = 8 (docs/baselines.md)."""


def model_of_context(
    context: Context, params: NeuronParams | None = None, allow_target_action: bool = False
) -> PlanningModel:
    """The exact :class:`PlanningModel` of a context: what an oracle knows."""
    params = NeuronParams() if params is None else params
    weights: np.ndarray = context.weights[None].astype(np.int8)  # [1, n, n]
    neurons = None
    if context.heterogeneity is not None:
        weights = (context.weights * context.heterogeneity.synaptic_scale)[None]
        neurons = neuron_parameters(
            params, context.heterogeneity.thresholds_mV[None],
            context.heterogeneity.time_constants_ms[None],
        )  # fmt: skip
    actions = legal_actions(context.n_neurons, context.target, allow_target_action, context.hidden)
    return PlanningModel(
        np.ascontiguousarray(weights), context.target, actions.astype(np.int64), params, neurons
    )


def plan_episode(
    context: Context,
    params: NeuronParams | None = None,
    width: int = DEFAULT_ORACLE_WIDTH,
    allow_target_action: bool = False,
    latency_steps: int = 0,
    light_mW_per_mm2: float | None = None,
) -> tuple[np.ndarray, float]:
    """Plan a whole episode of ``context`` knowing its weights (not its witness).

    Args:
        context: the task; its weights, target, pattern, hidden and heterogeneous
            neurons are used, its witness is not.
        params: the neuron model; the paper's when None.
        width: beam width (distinct simulator states kept per step).
        allow_target_action: whether stimulating the target is legal (an extension).
        latency_steps: loop latency L: the action chosen at step t lands at t + L.
        light_mW_per_mm2: None for the paper's current pulse; else the actuator is ChR2
            lit at this fibre-tip irradiance (``Extensions(actuator="chr2")``), and the
            search plays the opsin's state with the network's
            (:mod:`spikectl.planning.lit_search`).

    Returns:
        ``(actions, ret)``: int64 [N] simulator actions to choose (neuron indices, -1 =
        do nothing; never a hidden neuron nor, unless allowed, the target; the last L
        are -1, as they never land) and their return, checked by replaying the actions
        as they land (L steps later) with :func:`spikectl.simulate`.
    """
    if not isinstance(context, Context):
        raise TypeError(f"context must be a spikectl.Context, got {type(context).__name__}")
    params = NeuronParams() if params is None else params
    if not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams, got {type(params).__name__}")
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
        raise ValueError(f"width must be an integer >= 1, got {width!r}")
    if (isinstance(latency_steps, bool) or not isinstance(latency_steps, (int, np.integer))
            or not 0 <= latency_steps <= MAX_LATENCY_STEPS):  # fmt: skip
        raise ValueError(
            f"latency_steps must be an integer in 0..{MAX_LATENCY_STEPS}, got {latency_steps!r}"
        )
    model = model_of_context(context, params, allow_target_action)
    length, latency = context.episode_length, int(latency_steps)
    if light_mW_per_mm2 is not None:
        return _plan_lit(context, model, int(width), latency, light_mW_per_mm2)
    chosen = np.full(length, DO_NOTHING, dtype=np.int64)
    if latency < length:
        start = _state_after_idle_steps(model, latency)
        plan = beam_search(model, start, context.pattern, latency, int(width))
        chosen[: length - latency] = plan.actions
    landing = np.concatenate([np.full(latency, DO_NOTHING, dtype=np.int64), chosen])[:length]
    _, spikes = simulate(context.weights, landing, params, **context.simulate_kwargs())
    reward_if_spike, reward_if_silent = step_rewards(context.pattern)
    ret = float(np.where(spikes[:, context.target], reward_if_spike, reward_if_silent).sum())
    return chosen, ret


def _plan_lit(context: Context, model: PlanningModel, width: int, latency: int,
              light_mW_per_mm2: float) -> tuple[np.ndarray, float]:  # fmt: skip
    """:func:`plan_episode` through the ChR2 actuator (the opsins rest while nothing
    lands, so the first landing light meets the idle network and resting channels)."""
    length, params = context.episode_length, model.params
    opsin = OpsinActuator(1, model.n_neurons, light_mW_per_mm2, params.dt_ms,
                          params.capacitance_pF)  # fmt: skip
    chosen = np.full(length, DO_NOTHING, dtype=np.int64)
    if latency < length:
        start = (_state_after_idle_steps(model, latency), Occupancies.at_rest(1, model.n_neurons))
        chosen[: length - latency] = lit_beam_search(model, opsin, start, context.pattern,
                                                     latency, width).actions  # fmt: skip
    landing = np.concatenate([np.full(latency, DO_NOTHING, dtype=np.int64), chosen])[:length]
    spikes = lit_spikes(model, opsin, landing)
    reward_if_spike, reward_if_silent = step_rewards(context.pattern)
    ret = float(np.where(spikes[:, context.target], reward_if_spike, reward_if_silent).sum())
    return chosen, ret


def _state_after_idle_steps(model: PlanningModel, steps: int) -> SimulatorState:
    """The model's state after ``steps`` steps from rest with nothing stimulated: what the
    first action to land meets under a latency of ``steps``."""
    state = SimulatorState.at_rest(1, model.n_neurons, model.params)
    if steps:
        n = model.n_neurons
        advance(state, model.weights, np.full((1, steps), DO_NOTHING, dtype=np.int64),
                model.params, np.empty((1, steps, n)), np.empty((1, steps, n), dtype=bool),
                model.neurons)  # fmt: skip
    return state


def agent_actions(context: Context, actions: np.ndarray) -> np.ndarray:
    """Simulator actions (neuron indices) of ``context`` as the agent's indices."""
    if context.hidden is None:
        return actions.astype(np.int64)
    observed = np.searchsorted(context.observable, actions)
    return np.where(actions >= 0, observed, DO_NOTHING).astype(np.int64)


class OraclePlanner:
    """The oracle planner as a controller (a privileged reference, like the witness):
    at step 0 it plans the whole episode of the context named by
    ``info["context_index"]`` in ``contexts`` with :func:`plan_episode`, knowing its
    weights, then replays the plan open loop. Plans are kept per context (and latency),
    so a second episode of a context costs nothing; ``plan_seconds`` sums the CPU time
    spent planning.

    ``latency_steps``: the loop latency it plans for; None (the default) reads it from
    the observation (the length of ``actions_in_flight``, 0 without it), so it plans for
    the loop it plays; 0 under latency is the latency-unaware oracle.
    ``light_mW_per_mm2``: None plans for the paper's current pulse; else for the ChR2
    actuator at that irradiance (:func:`~spikectl.planning.lit_search.planned_light` of
    the environment's extensions).
    """

    def __init__(
        self,
        contexts: Sequence[Context],
        params: NeuronParams | None = None,
        width: int = DEFAULT_ORACLE_WIDTH,
        allow_target_action: bool = False,
        latency_steps: int | None = None,
        light_mW_per_mm2: float | None = None,
    ) -> None:
        self.contexts, self.params, self.width = contexts, params, width
        self.light_mW_per_mm2 = light_mW_per_mm2
        self.allow_target_action = allow_target_action
        self.latency_steps = latency_steps
        self.plans: dict[tuple[int, int], np.ndarray] = {}
        self.plan_seconds = 0.0
        self._plan: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the current episode's plan (the plans per context are kept)."""
        self._plan = None

    def plan(self, context: int, latency_steps: int = 0) -> np.ndarray:
        """The agent's actions [N] to choose for context index ``context`` under a loop
        latency of ``latency_steps`` (planned once)."""
        key = (context, latency_steps)
        if key not in self.plans:
            started = time.process_time()
            actions, _ = plan_episode(self.contexts[context], self.params, self.width,
                                      self.allow_target_action, latency_steps,
                                      self.light_mW_per_mm2)  # fmt: skip
            self.plans[key] = agent_actions(self.contexts[context], actions)
            self.plan_seconds += time.process_time() - started
        return self.plans[key]

    def _latency(self, observation: Mapping[str, Any]) -> int:
        """The latency planned for: its own, else the observation's (actions in flight)."""
        if self.latency_steps is not None:
            return self.latency_steps
        in_flight = observation.get(IN_FLIGHT_KEY)
        return 0 if in_flight is None else int(np.shape(in_flight)[-1])

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The planned action for this step of the context ``info["context_index"]``."""
        check_controller_input(observation, info, "OraclePlanner")
        step = int(observation["step"])
        if step == 0 or self._plan is None:
            if "context_index" not in info:
                raise ValueError(
                    "OraclePlanner plans the context it is told and needs "
                    "info['context_index'] (an index into its contexts)"
                )
            self._plan = self.plan(int(info["context_index"]), self._latency(observation))
        return int(self._plan[step])

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        """The planned actions [S] of a vector environment's batch, one per sub-environment."""
        contexts = np.asarray(infos["context_index"], dtype=np.int64)  # [S]
        steps = np.asarray(observations["step"], dtype=np.int64)  # [S]
        latency = self._latency(observations)
        return np.array(
            [self.plan(int(context), latency)[step]
             for context, step in zip(contexts, steps, strict=True)],
            dtype=np.int64,
        )  # fmt: skip
