"""Identify-and-plan's decision rule: greedy beam re-planning on the current estimate, and
the expected-return choice (QMDP) where the controller would probe.

Each step the controller plans with the beam search (:func:`~spikectl.planning.beam.
beam_search`, ``width`` states a step, ``horizon`` steps ahead) on the estimate's planning
weights (with ``hypotheses`` K > 1: one action sequence for its mean return over K
networks drawn from the estimate, so that a light whose effect the estimate doubts is
weighed by what it may do), and keeps the plan while it holds: the model is
deterministic, so an unchanged estimate from an unsurprising state gives the same plan.
It re-plans when the weights or the planned neurons change, when the network did
something the last plan did not predict, or when less than half the horizon is left (a
receding horizon, so that a wanted spike just past the plan's end is seen in time).

Where the plan misses a wanted spike and would do nothing now, the prober's action is
taken; with ``gamble`` set, the action of highest expected return over networks drawn
from the estimate instead (:func:`~spikectl.planning.qmdp.qmdp_action`). Under
stochastic release, where the plan misses the spike wanted at the next step, the target's
known excitatory input with the highest release chance is stimulated even before its
vesicles are back by the paper's rule (:meth:`DecisionSettings.under_release`; +0.008
network by network on the ``stochastic`` sets, docs/results/unrested-inputs).

Under loop latency L (docs/extensions.md) an action chosen at step s lands at s + L,
after the L actions already in flight: the rule decides for that step, from the state
the estimate predicts there (:meth:`DecisionSettings.state_met`), as the oracle does with
the true network; with L = 0 that is the tracked state itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.neuron.simulator import DO_NOTHING, SimulatorState
from spikectl.planning.beam import PlanningModel
from spikectl.planning.in_flight import state_after
from spikectl.planning.qmdp import QMDPSettings
from spikectl.planning.relays import relay_weights

DEFAULT_HORIZON = 20
"""Steps each re-plan looks ahead."""


@dataclass(frozen=True)
class Situation:
    """What one decision is taken on (the observation's episode facts).

    Attributes:
        step: the step the decided action stimulates at: the episode step now, plus the
            loop's latency.
        target: the rewarded neuron.
        pattern: [N] bool the episode's target pattern.
        mask: [n + 1] bool the legal actions (do nothing first).
    """

    step: int
    target: int
    pattern: np.ndarray
    mask: np.ndarray

    @property
    def actions(self) -> np.ndarray:
        """int64 [A] the legal simulator actions, do nothing (-1) first."""
        return (np.flatnonzero(self.mask) + DO_NOTHING).astype(np.int64)


@dataclass(frozen=True)
class DecisionSettings:
    """The decision rule's settings.

    Attributes:
        width: beam width of each re-plan.
        horizon: steps each re-plan looks ahead; None: to the end of the episode.
        gamble: where the controller would probe, choose by expected return over
            networks drawn from the estimate (QMDP) with these settings; None: probe.
        hypotheses: K, the networks each re-plan plans one action sequence on, drawn
            from the estimate by the episode's uniforms (common random numbers), for
            the best mean return over them; 1: the estimate's planning weights alone.
    """

    width: int = 32
    horizon: int | None = DEFAULT_HORIZON
    gamble: QMDPSettings | None = None
    hypotheses: int = 1

    def __post_init__(self) -> None:
        for name in ("width", "hypotheses"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if self.horizon is not None and (
            isinstance(self.horizon, bool) or not isinstance(self.horizon, (int, np.integer))
            or self.horizon < 1
        ):  # fmt: skip
            raise ValueError(f"horizon must be an integer >= 1 or None, got {self.horizon!r}")
        if self.gamble is not None and not isinstance(self.gamble, QMDPSettings):
            raise TypeError(f"gamble must be a QMDPSettings or None, got {self.gamble!r}")

    @property
    def replan_margin(self) -> int:
        """A plan is renewed when fewer steps than this are left of it."""
        return 1 if self.horizon is None else max(1, self.horizon // 2)

    @property
    def draws(self) -> int:
        """Networks the episode's uniforms must draw (one draw per episode, reused by
        every decision: common random numbers; QMDP and the planned hypotheses share
        them)."""
        gamble = 0 if self.gamble is None else self.gamble.networks
        return max(gamble, self.hypotheses if self.hypotheses > 1 else 0)

    def planning_model(self, policy, weights: np.ndarray, situation: Situation) -> PlanningModel:
        """The networks the beam search plans on (``policy``: the controller, for its
        estimate, neuron model and planned neurons): the planning weights, or
        :attr:`hypotheses` networks drawn from the estimate."""
        if self.hypotheses == 1:
            networks = weights[None].copy()
        else:
            k = self.hypotheses
            uniforms = (policy.uniforms[0][:k], policy.uniforms[1][:k])
            networks = policy.estimate.sample(policy.known_sd, *uniforms)  # [K, n, n]
            if policy.plans_relays:  # [K, 2n, 2n]
                relays = policy.estimate.relay_signs(policy.known_sd)
                networks = np.stack([relay_weights(drawn, relays) for drawn in networks])
        return PlanningModel(networks, situation.target, situation.actions, policy.params,
                             policy.planned_neurons())  # fmt: skip

    def state_met(self, policy, weights: np.ndarray) -> SimulatorState:
        """The planning state an action chosen now meets when it lands: the present one
        (``policy.planning_state()``) stepped through the actions in flight on the
        planning ``weights``; the present one itself without latency."""
        state, in_flight = policy.planning_state(), policy.reader.in_flight
        if not in_flight.steps:
            return state
        return state_after(state, weights, in_flight.actions, policy.params,
                           policy.planned_neurons())  # fmt: skip

    def under_release(self, policy, weights: np.ndarray, known: np.ndarray,
                      situation: Situation, action: int) -> int:  # fmt: skip
        """Under stochastic release, where the plan does not hit the spike wanted at the
        next step: the target's known excitatory input (not refractory, legal) with the
        highest release chance, which the plan's deterministic rule counts as silent
        until its vesicles are back; else ``action``."""
        step, target, pattern = situation.step, situation.target, situation.pattern
        offset = step - policy.plan_start + 1  # the action reaches the target a step later
        if step + 1 >= pattern.shape[0] or not pattern[step + 1]:
            return action
        plan = policy.plan
        if offset < plan.rewards.shape[0] and plan.rewards[offset] > 0:
            return action
        state = policy.observed_state_met()
        n = known.shape[0]  # weights also holds the relays where they are planned
        inputs = (known[:, target] & (weights[:n, target] > 0)
                  & (state.refractory_left[0] == 0) & situation.mask[1:])  # fmt: skip
        if not inputs.any():
            return action
        # At the coming step; 0 where not an input.
        chance = policy.reader.chances_after(inputs, state.steps_since_release[0])
        return int(np.argmax(chance))
