"""Identify-and-plan: model-predictive control on a connectivity estimated online.

The controller knows the neuron model (``NeuronParams``) but not the weights. It is a
:class:`~spikectl.planning.composition.Composition` of four parts; each step it

1. reads the new observation with its **observation** part into its tracked simulator
   state and the step's evidence, which its **estimator** adds to its estimate of G;
2. re-plans by its **decision** rule (the beam search on the estimate's planning weights)
   whenever the weights or planned neurons changed, the network did not do what the last
   plan predicted, or the plan runs short; otherwise the last plan still holds;
3. when the plan misses a wanted target spike (the estimate is too uncertain to plan)
   and would do nothing now, it takes its **prober**'s action (a neuron whose row is
   unknown and that most probably excites the target: its row shows at the next step),
   or with QMDP in the decision rule the action of highest expected return over
   networks drawn from the estimate.

The named controller ``identify-and-plan`` plays the composition
:func:`~spikectl.planning.named.named_composition` declares for the environment. It acts
through the public interface only (observation and ``info["action_mask"]``) and never
takes an illegal action.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spikectl.envs.controller import ControllerInputError, check_controller_input
from spikectl.envs.sensing import SPIKES_KEY, VOLTAGE_KEY
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, advance, uniform_neuron_parameters
from spikectl.planning.beam import Plan, PlanningModel, beam_search
from spikectl.planning.composition import Composition
from spikectl.planning.deciding import Situation
from spikectl.planning.estimators import RIG_SPIKE_ESTIMATORS, SPIKE_ESTIMATORS
from spikectl.planning.identify import KnownConnectivity
from spikectl.planning.in_flight import first_neurons, latency_of
from spikectl.planning.lit_search import (
    lit_beam_search,
    lit_state_after,
    lit_step,
    network_model,
    tracked_occupancies,
)
from spikectl.planning.observing import Reader
from spikectl.planning.probing import ready_neurons
from spikectl.planning.qmdp import Episode, qmdp_action
from spikectl.planning.relays import relay_state


class IdentifyAndPlan:
    """A training-free controller: identify the connectivity, then plan (MPC).

    Args:
        params: the neuron model; the paper's (Table 1) when None.
        composition: the parts (:class:`~spikectl.planning.composition.Composition`);
            None: the paper's model (its defaults).
        extensions: the environment's (None: the paper's): its measurement noise always,
            and the rest where the composition's observation part reads the task's
            model (``task_model``).
        told_weights: [n, n] the network's true signed weights (agent indexing): the same
            loop *told* the connectivity, with nothing left to identify (a privileged
            controller near the oracle planner; a teacher of the guided learner).
        seed: seeds the networks QMDP draws (one draw per episode: ``seed`` and the
            number of episodes this controller has started); :meth:`spawn`'s copies (one
            per sub-environment of a vector environment) get ``seed + index``.

    ```python
    policy = IdentifyAndPlan()
    obs, info = env.reset(seed=0)
    policy.reset()
    while True:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    ```
    """

    def __init__(
        self,
        params: NeuronParams | None = None,
        composition: Composition | None = None,
        *,
        extensions: Extensions | None = None,
        told_weights: np.ndarray | None = None,
        seed: int = 0,
    ) -> None:
        params = NeuronParams() if params is None else params
        if not isinstance(params, NeuronParams):
            raise TypeError(f"params must be a NeuronParams, got {type(params).__name__}")
        composition = Composition() if composition is None else composition
        if not isinstance(composition, Composition):
            raise TypeError(f"composition must be a Composition, got {type(composition).__name__}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        if told_weights is not None:
            told_weights = np.asarray(told_weights)
            if told_weights.ndim != 2 or told_weights.shape[0] != told_weights.shape[1]:
                raise ValueError(
                    f"told_weights must be a square [n, n] array, got shape {told_weights.shape}"
                )
            if not np.isin(told_weights, (-1, 0, 1)).all():
                raise ValueError("told_weights must hold only -1, 0 and +1")
        self.params, self.composition, self.seed = params, composition, int(seed)
        self.extensions, self.told_weights = extensions, told_weights
        self.observation = composition.observation.bind(params, extensions)
        spike_filter = composition.estimator.kind in SPIKE_ESTIMATORS
        if spike_filter and self.observation.spikes_only and (
            (composition.estimator.kind in RIG_SPIKE_ESTIMATORS)
            != composition.observation.task_model
        ):
            raise ValueError(
                "identify-and-plan reads spikes with the 'spike-likelihood' estimator under "
                "the task's model (task_model=True), and with 'spikes' without it; composition "
                f"{composition.name!r} keeps {composition.estimator.kind!r} with "
                f"task_model={composition.observation.task_model}"
            )
        if self.observation.spikes_only != spike_filter or (
            spike_filter and told_weights is not None
        ):
            raise ValueError(
                "identify-and-plan identifies from spikes alone with the 'spikes' estimator "
                "(without told weights), and from potentials with the others; composition "
                f"{composition.name!r} keeps {composition.estimator.kind!r} on an environment "
                f"that observes {'spikes' if self.observation.spikes_only else 'potentials'}"
            )
        self.known_sd = composition.estimator.known_sd
        self.noise_mV = self.observation.noise_mV
        self.reset()

    @property
    def plans_relays(self) -> bool:
        """Whether the plan holds virtual relay neurons: the estimator keeps relays and the
        weights are not told (told weights are the observed neurons' alone)."""
        return self.composition.estimator.plans_relays and self.told_weights is None

    def reset(self) -> None:
        """Forget the episode (call at each episode's start; ``act`` at step 0 also does)."""
        self.estimate = None
        self.reader: Reader | None = None
        self.plan: Plan | None = None
        self.plan_start = 0
        self._planned_weights: np.ndarray | None = None
        self._planned_neurons: np.ndarray | None = None
        self._predicted_spikes: np.ndarray | None = None
        # The planning weights of the estimate's last version, and what each step of the
        # plan has still ahead that it misses (both pure functions, kept: issue 24).
        self._weights_of: tuple[int, int] | None = None
        self._weights_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._misses_from: np.ndarray | None = None
        self.probes = 0
        self.gambles = 0
        self.replans = 0
        self._episodes = getattr(self, "_episodes", -1) + 1
        self.uniforms: tuple[np.ndarray, np.ndarray] | None = None
        self._state_met = None  # the decision's state_met, computed once a step
        self._occupancies_met = None  # ChR2: the opsins' state the light chosen now meets

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The action for this observation (an agent index, -1 for do nothing)."""
        check_controller_input(observation, info, "IdentifyAndPlan")
        sensed_key = SPIKES_KEY if self.observation.spikes_only else VOLTAGE_KEY
        if sensed_key not in observation:
            raise ControllerInputError(
                f"IdentifyAndPlan.act: it was built for an environment that observes "
                f"{sensed_key!r}, and this observation has none (pass the environment's "
                "extensions: sensing='spikes' observes spikes in place of potentials)"
            )
        step = int(observation["step"])
        sensed = np.asarray(observation[sensed_key], dtype=np.float64)
        mask = np.asarray(info["action_mask"], dtype=bool)
        n = sensed.shape[0]
        if mask.shape != (n + 1,):
            raise ValueError(f"action_mask must have shape [{n + 1}], got {mask.shape}")
        if step == 0 or self.reader is None:
            if step != 0:
                raise ValueError("IdentifyAndPlan must see the episode from its first step")
            self._start_episode(n, latency_of(observation))
            self.reader.in_flight.read(observation)
        else:
            self.estimate.add(*self.reader.read_landed(observation, sensed, self.estimate))
            self.reader.settle(self.estimate)
        pattern = np.asarray(observation["pattern"], dtype=bool)
        if step >= pattern.shape[0]:
            raise ValueError(f"the episode has ended (step {step}): reset before acting")
        # Under latency the action chosen now lands (and is planned for) L steps later.
        lands = step + self.reader.in_flight.steps
        weights, known = self.planning_weights()
        landing_now = self.reader.in_flight.landing_now
        if lands >= pattern.shape[0]:  # it would never land
            self._predict(weights, landing_now)
            return DO_NOTHING
        situation = Situation(lands, int(observation["target"]), pattern, mask)
        self._state_met = None
        surprised = self._predicted_spikes is not None and not np.array_equal(
            self._predicted_spikes, self.reader.tracker.spiked
        )
        if (
            self.plan is None
            or surprised
            or not np.array_equal(weights, self._planned_weights)
            or not np.array_equal(self.planned_neurons(), self._planned_neurons)
            or self._plan_remaining(lands, pattern.shape[0])
            < self.composition.decision.replan_margin
        ):
            self._replan(weights, situation)
        offset = lands - self.plan_start
        action = int(self.plan.actions[offset])
        if action == DO_NOTHING and self._misses_wanted_spikes(pattern, offset):
            if self.composition.decision.gamble is not None:
                action = self._gamble(known, situation)
            else:
                action = self._probe(known, situation)
        if self.observation.stochastic_release:
            action = self.composition.decision.under_release(self, weights, known, situation,
                                                             action)  # fmt: skip
        self._predict(weights, action if landing_now is None else landing_now)
        return action

    def _start_episode(self, n: int, latency_steps: int) -> None:
        """Forget the last episode; a fresh reader (in a loop of ``latency_steps``) and
        estimate for ``n`` neurons, and the episode's uniforms where the decision rule
        draws networks."""
        self.reset()
        self.reader = self.observation.reader(n, latency_steps)
        self.estimate = self._new_estimate(n)
        draws = self.composition.decision.draws
        if draws:
            # One draw per episode, reused by every decision: networks change only where
            # the estimate does (common random numbers).
            rng = np.random.default_rng([self.seed, self._episodes])
            self.uniforms = (rng.random((draws, n, n)), rng.random((draws, n)))

    def _new_estimate(self, n: int):
        if self.told_weights is not None:
            if self.told_weights.shape != (n, n):
                raise ValueError(
                    f"told_weights has shape {self.told_weights.shape}, but the "
                    f"observation has {n} neurons"
                )
            return KnownConnectivity(self.told_weights)
        observation = self.observation
        return self.composition.estimator.new(n, observation.residual_sd, observation.model,
                                              self.params)  # fmt: skip

    def planning_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """(weights to plan with, known [n, n]) of the estimate
        (:meth:`~spikectl.planning.estimators.EstimatorSettings.planning_weights`),
        computed again only when the estimate has changed."""
        of = (id(self.estimate), self.estimate.version)  # reset() forgets it
        if of != self._weights_of:
            self._weights_cache = self._compute_planning_weights()
            self._weights_of = of
        return self._weights_cache

    def _compute_planning_weights(self) -> tuple[np.ndarray, np.ndarray]:
        observation = self.observation
        return self.composition.estimator.planning_weights(
            self.estimate, observation.plan_mean, observation.strengths, self.plans_relays
        )

    def planned_neurons(self) -> np.ndarray | None:
        """[1, 2, m] per-neuron kernel parameters to plan with where the reader's tracker
        has its own, the paper's for virtual relay neurons; else None (the paper's)."""
        neurons = self.reader.neurons()
        if neurons is not None and self.plans_relays:
            relays = uniform_neuron_parameters(self.params, 1, neurons.shape[-1])
            neurons = np.ascontiguousarray(np.concatenate([neurons, relays], axis=-1))
        return neurons

    def planning_state(self):
        """The simulator state the plan starts from: the tracker's, with the virtual
        relay neurons' appended where the controller plans relays."""
        if self.plans_relays:
            return relay_state(self.reader.tracker.state, self.params)
        return self.reader.tracker.state

    def state_met(self):
        """The planning state the action chosen now meets when it lands (the decision
        rule's :meth:`~spikectl.planning.deciding.DecisionSettings.state_met`: under
        latency the present one stepped through the actions in flight)."""
        if self._state_met is None and self.reader.opsin is not None:
            # ChR2: the light in flight lands on the tracked occupancies too.
            weights, opsin = self.planning_weights()[0], self.reader.opsin
            self._state_met, self._occupancies_met = lit_state_after(
                network_model(weights, self.params, self.planned_neurons()), opsin,
                self.planning_state(), tracked_occupancies(opsin, weights.shape[0]),
                self.reader.in_flight.actions,
            )  # fmt: skip
        if self._state_met is None:
            self._state_met = self.composition.decision.state_met(self, self.planning_weights()[0])
        return self._state_met

    def observed_state_met(self):
        """:meth:`state_met` of the observed neurons alone (the tracked state without
        latency)."""
        if not self.reader.in_flight.steps:
            return self.reader.tracker.state
        n = self.reader.tracker.spiked.shape[0]
        return first_neurons(self.state_met(), n)

    def ready(self) -> np.ndarray:
        """[n] neurons that release if they spike when the chosen action lands (not
        refractory, vesicles back)."""
        return ready_neurons(self.observed_state_met(), self.params)

    def _replan(self, weights: np.ndarray, situation: Situation) -> None:
        model = self._model(weights, situation)
        decision, step, pattern = self.composition.decision, situation.step, situation.pattern
        if self.reader.opsin is not None:  # ChR2: plan the light with the opsins' state
            start = self.state_met(), self._occupancies_met
            self.plan = lit_beam_search(model, self.reader.opsin, start, pattern, step,
                                        decision.width, decision.horizon)  # fmt: skip
        else:
            self.plan = beam_search(
                model, self.state_met(), pattern, step, decision.width, decision.horizon
            )
        self.plan_start = step
        self._planned_weights = weights
        self._planned_neurons = model.neurons
        # Whether the plan misses a wanted spike from each of its steps on.
        wanted = pattern[step : step + self.plan.rewards.shape[0]]
        missing = wanted & (self.plan.rewards == 0)
        self._misses_from = np.logical_or.accumulate(missing[::-1])[::-1]
        self.replans += 1

    def _model(self, weights: np.ndarray, situation: Situation) -> PlanningModel:
        return self.composition.decision.planning_model(self, weights, situation)

    def _plan_remaining(self, step: int, episode_length: int) -> float:
        """Steps of the current plan still ahead of ``step`` (inf when it reaches the end)."""
        end = self.plan_start + self.plan.actions.shape[0]
        return np.inf if end >= episode_length else end - step

    def _misses_wanted_spikes(self, pattern: np.ndarray, offset: int) -> bool:
        """True when the current plan does not hit every wanted spike still ahead of its
        step ``offset`` (the pattern is the episode's, the one the plan was made for)."""
        return bool(self._misses_from[offset])

    def _probe(self, known: np.ndarray, situation: Situation, count: bool = True) -> int:
        """The prober's action (:meth:`~spikectl.planning.probing.ProberSettings.choose`)."""
        action = self.composition.prober.choose(self.estimate, self.known_sd, known,
                                                self.ready(), situation.target,
                                                situation.mask)  # fmt: skip
        self.probes += count and action != DO_NOTHING
        return action

    def _gamble(self, known: np.ndarray, situation: Situation) -> int:
        """The action of highest expected return over the episode's networks drawn from
        the estimate, plus the information bonus (:func:`~spikectl.planning.qmdp.
        qmdp_action`)."""
        settings, target = self.composition.decision.gamble, situation.target
        probe = self._probe(known, situation, count=False)
        uniforms = (draws[: settings.networks] for draws in self.uniforms)
        episode = Episode(situation.pattern, target, situation.actions, self.params)
        action = qmdp_action(
            self.estimate.sample(self.known_sd, *uniforms),
            self.estimate.excitation_probability(target, self.known_sd),
            self.observed_state_met(), self.ready() & ~known[:, target], probe, episode,
            situation.step, settings,
        )  # fmt: skip
        self.probes += action != DO_NOTHING
        self.gambles += 1
        return action

    def _predict(self, weights: np.ndarray, action: int) -> None:
        """The spikes the estimate predicts for the coming step, in which ``action``
        lands (to detect surprises)."""
        state = self.planning_state().copy()
        m = weights.shape[0]  # the observed neurons, and their relays where planned
        voltage, spikes = np.empty((1, 1, m)), np.empty((1, 1, m), dtype=bool)
        actions = np.array([[action]], dtype=np.int64)
        opsin = self.reader.opsin
        if opsin is not None:  # ChR2: the step's drive is the tracked opsins' current
            spikes[0, 0] = lit_step(network_model(weights, self.params, self.planned_neurons()),
                                    opsin, state, tracked_occupancies(opsin, m), actions[0],
                                    np.ascontiguousarray(weights[None]))[0]  # fmt: skip
        else:
            advance(state, np.ascontiguousarray(weights[None]), actions, self.params, voltage,
                    spikes, self.planned_neurons())  # fmt: skip
        self._predicted_spikes = spikes[0, 0, : self.reader.tracker.spiked.shape[0]]

    def spawn(self, index: int) -> IdentifyAndPlan:
        """A fresh copy with the same parts, seeded ``seed + index``: what
        :func:`spikectl.envs.controller.batched` plays in sub-environment ``index``."""
        return IdentifyAndPlan(self.params, self.composition, extensions=self.extensions,
                               told_weights=self.told_weights, seed=self.seed + index)  # fmt: skip
