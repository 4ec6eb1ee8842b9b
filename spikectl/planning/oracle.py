"""The oracle planner: the best return the planner finds when it knows the weights.

It knows the context's connectivity (and heterogeneous neurons, if any) but not its
witness, and searches action sequences from rest with :func:`beam_search`. Its return
is a context's reachable return found without the witness: the headroom a
topology-agnostic controller is chasing. :class:`OraclePlanner` plays it as a
controller (``reset()`` / ``act(observation, info)``).
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
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, neuron_parameters, simulate
from spikectl.planning.beam import PlanningModel, beam_search

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
) -> tuple[np.ndarray, float]:
    """Plan a whole episode of ``context`` knowing its weights (not its witness).

    Args:
        context: the task; its weights, target, pattern, hidden and heterogeneous
            neurons are used, its witness is not.
        params: the neuron model; the paper's when None.
        width: beam width (distinct simulator states kept per step).
        allow_target_action: whether stimulating the target is legal (an extension).

    Returns:
        ``(actions, ret)``: int64 [N] simulator actions (neuron indices, -1 = do
        nothing; never a hidden neuron nor, unless allowed, the target) and their
        return, checked by replaying them with :func:`spikectl.simulate`.
    """
    if not isinstance(context, Context):
        raise TypeError(f"context must be a spikectl.Context, got {type(context).__name__}")
    params = NeuronParams() if params is None else params
    if not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams, got {type(params).__name__}")
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
        raise ValueError(f"width must be an integer >= 1, got {width!r}")
    model = model_of_context(context, params, allow_target_action)
    start = SimulatorState.at_rest(1, context.n_neurons, params)
    plan = beam_search(model, start, context.pattern, 0, int(width))
    _, spikes = simulate(context.weights, plan.actions, params, **context.simulate_kwargs())
    reward_if_spike, reward_if_silent = step_rewards(context.pattern)
    ret = float(np.where(spikes[:, context.target], reward_if_spike, reward_if_silent).sum())
    return plan.actions, ret


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
    weights, then replays the plan open loop. Plans are kept per context, so a second
    episode of a context costs nothing; ``plan_seconds`` sums the CPU time spent
    planning.
    """

    def __init__(
        self,
        contexts: Sequence[Context],
        params: NeuronParams | None = None,
        width: int = DEFAULT_ORACLE_WIDTH,
        allow_target_action: bool = False,
    ) -> None:
        self.contexts, self.params, self.width = contexts, params, width
        self.allow_target_action = allow_target_action
        self.plans: dict[int, np.ndarray] = {}
        self.plan_seconds = 0.0
        self._plan: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the current episode's plan (the plans per context are kept)."""
        self._plan = None

    def plan(self, context: int) -> np.ndarray:
        """The agent's actions [N] for context index ``context`` (planned once)."""
        if context not in self.plans:
            started = time.process_time()
            actions, _ = plan_episode(
                self.contexts[context], self.params, self.width, self.allow_target_action
            )
            self.plans[context] = agent_actions(self.contexts[context], actions)
            self.plan_seconds += time.process_time() - started
        return self.plans[context]

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
            self._plan = self.plan(int(info["context_index"]))
        return int(self._plan[step])

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        """The planned actions [S] of a vector environment's batch, one per sub-environment."""
        contexts = np.asarray(infos["context_index"], dtype=np.int64)  # [S]
        steps = np.asarray(observations["step"], dtype=np.int64)  # [S]
        return np.array(
            [self.plan(int(context))[step] for context, step in zip(contexts, steps, strict=True)],
            dtype=np.int64,
        )
