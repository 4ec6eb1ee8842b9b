"""Identify-and-plan: model-predictive control on a connectivity estimated online.

The policy knows the neuron model (``NeuronParams``) but not the weights. Each step it

1. reads the new observation into its tracked simulator state and adds the step's
   residuals to its :class:`~spikectl.planning.identify.ConnectivityEstimate`;
2. re-plans with the beam search on the current estimate (known entries rounded to
   {-1, 0, +1}, unknown ones at their posterior mean) whenever the estimate changed
   or the network did not do what the last plan predicted; otherwise the last plan
   still holds;
3. when the plan misses a wanted target spike (the estimate is too uncertain to
   plan) and would do nothing now, it *probes*: it stimulates the ready neuron whose
   outgoing weights are still unknown and that most probably excites the target,
   which reveals that neuron's whole row at the next step. With
   ``gamble_networks=K`` it instead takes the action of highest expected return over
   K networks drawn from the estimate (QMDP, :mod:`spikectl.planning.qmdp`), plus a
   bonus for what the action teaches about the target's inputs.

Under the extensions (``extensions=``, ``identification="bayes"``,
``filter_voltage=True``) it learns with the task's own observation model: measurement
noise, release chances under stochastic release, background input, synaptic spread
(:mod:`spikectl.planning.bayes`; under stochastic release alone each release is read
back from the next step's residuals, :mod:`spikectl.planning.release`, and where the
plan misses the next wanted spike a known input is stimulated at its release chance,
rested or not), and plans from potentials filtered against the model
(:mod:`spikectl.planning.filtering`). With hidden neurons (``relays=True``) it also
learns each observed neuron's effect two steps after its release, through hidden
neurons, and plans with it (:mod:`spikectl.planning.relays`).
:func:`environment_settings` is what the named controller ``identify-and-plan`` plays
on an environment; the constructor's defaults are the paper's model.

It acts through the public interface only (observation and ``info["action_mask"]``)
and never takes an illegal action.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spikectl.envs.controller import check_controller_input
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.kernel import SINCE_RELEASE_CAP
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, advance, uniform_neuron_parameters
from spikectl.planning.bayes import BayesConnectivityEstimate, ObservationModel, release_chances
from spikectl.planning.beam import Plan, PlanningModel, beam_search
from spikectl.planning.discrete import DiscreteConnectivityEstimate, column_hypotheses_fit
from spikectl.planning.filtering import FilteredState, model_variance
from spikectl.planning.heterogeneity import NeuronTracker, tracks_neurons
from spikectl.planning.identify import (
    ConnectivityEstimate,
    KnownConnectivity,
    ObservedState,
    residual_sd,
)
from spikectl.planning.particles import ParticleConnectivityEstimate
from spikectl.planning.qmdp import qmdp_action
from spikectl.planning.relays import RelayConnectivityEstimate, relay_state, relay_weights
from spikectl.planning.release import exact_residuals, settled_releases

IDENTIFICATIONS = ("gaussian", "discrete", "bayes", "particles")
"""How the policy identifies G: a Gaussian posterior (ridge regression, any n), the
exact posterior over {-1, 0, +1} (n <= 11), that posterior under the task's own
observation model (:mod:`spikectl.planning.bayes`; the Gaussian one above n = 11), or
the posterior over {-1, 0, +1} on the entries the evidence touched, its likeliest
hypotheses per column (:mod:`spikectl.planning.particles`, any n)."""

# The constructor's arguments besides ``params``, each kept as an attribute of that name
# (what :meth:`IdentifyAndPlan.spawn` copies).
_SETTINGS = (
    "width", "horizon", "known_sd", "noise_mV", "hypotheses", "seed", "probe",
    "identification", "plan_on", "spike_margin_sd", "gamble_networks",
    "gamble_information", "gamble_horizon", "gamble_width", "gamble_candidates",
    "known_weights", "extensions", "filter_voltage", "settle_releases", "unrested_inputs",
    "relays",
)  # fmt: skip


GAMBLE_FROM_NEURONS = 16
"""From this many neurons on, the named ``identify-and-plan`` chooses where it would
probe by expected return over networks drawn from its estimate (QMDP,
``gamble_networks=GAMBLE_NETWORKS``): chosen on the suite's ``n16`` and ``n32``
validation sets (docs/baselines.md); at n = 8 it costs about 5x the CPU time for a gain
within noise, and it is off."""
GAMBLE_NETWORKS = 16
"""K, the networks QMDP draws from the estimate where :data:`GAMBLE_FROM_NEURONS` turns
it on."""
KNOWN_SD_LARGE = 0.35
"""From :data:`GAMBLE_FROM_NEURONS` neurons on, the named controller counts a weight as
known below this posterior standard deviation (the constructor's 0.25 elsewhere). The
generator's prior already puts the synapses of pairs more than 8 neurons apart below it
(prior sd 0.1 beyond 12, 0.32 within 12, 0.45 within 8, 0.55 within 4), so the planner
probes only the target's neighbours and plans sooner on what it knows: chosen on the
``n16`` and ``n32`` validation sets (the best mean of the two, docs/baselines.md)."""
PARTICLES_FROM_NEURONS = 32
"""From this many neurons on, the named controller (not its fast form) identifies with the
discrete posterior kept by particles (``identification="particles"``) where the task's
extensions ask for nothing of their own (the other tasks keep theirs): chosen on the ``n32``
validation set with QMDP, where it also takes less CPU time, and checked on training
networks; on ``n16`` it did not score more, so 16 neurons keep the Gaussian estimate
(docs/results/particles)."""
KNOWN_SD_STOCHASTIC_RELEASE = 0.4
"""Under stochastic release (fewer than :data:`GAMBLE_FROM_NEURONS` neurons), the same
threshold, chosen on the ``stochastic`` validation set: a failed release teaches little,
and waiting for certainty costs wanted spikes."""
KNOWN_SD_BACKGROUND = 0.35
"""Under background input (fewer than :data:`GAMBLE_FROM_NEURONS` neurons), the same
threshold, chosen on the ``background`` validation set."""
KNOWN_SD_FAST_LARGE = 0.4
"""From :data:`GAMBLE_FROM_NEURONS` neurons on, where every decision must be fast
(``environment_settings(..., fast=True)``: a teacher labelling every step of training),
QMDP is off and a weight counts as known below this posterior standard deviation: chosen
on the ``n16`` and ``n32`` validation sets without QMDP (the best mean of the two sizes,
docs/baselines.md), where it scores about as well as the QMDP setting at about a
hundredth of its CPU time."""


def environment_settings(
    extensions: Extensions | None, n_neurons: int | None = None, fast: bool = False
) -> dict[str, Any]:
    """The settings the named controller ``identify-and-plan`` plays on an environment
    with ``extensions`` and ``n_neurons`` observed neurons (``spikectl benchmark``,
    ``spikectl realtime``, ``spikectl.load_controller``), chosen on the suite's
    validation sets (docs/baselines.md): under measurement noise the Bayes observation
    model with filtered potentials (``identification="bayes"``, ``filter_voltage=True``);
    under stochastic release the extensions (the Gaussian estimate learns from each
    spike's release chance) and :data:`KNOWN_SD_STOCHASTIC_RELEASE`; under background
    input :data:`KNOWN_SD_BACKGROUND`; with heterogeneous neurons the extensions (each
    neuron's threshold and leak learned, :mod:`spikectl.planning.heterogeneity`, and
    known synapses planned at their estimated strength); with hidden neurons (and none
    of the above) the relays through them (``relays=True``); from
    :data:`GAMBLE_FROM_NEURONS` neurons on, QMDP where it would probe and
    :data:`KNOWN_SD_LARGE` (which then takes precedence: a combination no suite task
    has), and from :data:`PARTICLES_FROM_NEURONS` on, where the task asks for none of
    the above, the particle posterior; elsewhere the constructor's defaults.
    ``fast=True`` gives the form whose every decision is fast, which the guided learner's
    teacher plays (its labels cover every step of training): the same but for QMDP and
    the particles, replaced from :data:`GAMBLE_FROM_NEURONS` neurons on by
    :data:`KNOWN_SD_FAST_LARGE` alone. On the paper's task both forms are the
    constructor's defaults."""
    settings: dict[str, Any] = {}
    if n_neurons is not None and n_neurons >= GAMBLE_FROM_NEURONS:
        settings = (
            {"known_sd": KNOWN_SD_FAST_LARGE}
            if fast
            else {"gamble_networks": GAMBLE_NETWORKS, "known_sd": KNOWN_SD_LARGE}
        )
    own = _task_settings(extensions)
    if own is not None:
        return {**own, **settings}
    if n_neurons is not None and n_neurons >= PARTICLES_FROM_NEURONS and not fast:
        settings["identification"] = "particles"
    return settings


def _task_settings(extensions: Extensions | None) -> dict[str, Any] | None:
    """What the task's extensions make the named controller play, or None where they
    ask for nothing of their own (the paper's dynamics)."""
    if extensions is None:
        return None
    if extensions.observation_noise_mV > 0:
        return {"identification": "bayes", "extensions": extensions, "filter_voltage": True}
    if extensions.stochastic_release:
        return {"extensions": extensions, "known_sd": KNOWN_SD_STOCHASTIC_RELEASE}
    if extensions.background_rate > 0:
        return {"known_sd": KNOWN_SD_BACKGROUND}
    if extensions.heterogeneous:
        return {"extensions": extensions}
    if extensions.hidden_neurons or extensions.hidden_fraction:
        return {"relays": True}
    return None


class IdentifyAndPlan:
    """A training-free controller: identify the connectivity, then plan (MPC).

    Args:
        params: the neuron model; the paper's (Table 1) when None.
        width: beam width of each re-plan.
        horizon: steps each re-plan looks ahead; None: to the end of the episode.
        known_sd: a weight counts as known when its posterior standard deviation (in
            units of w_in) is below this.
        noise_mV: the measurement noise the policy assumes (0: the paper). It sets the
            residual noise of the estimate and lowers the spike threshold it reads
            spikes with by ``spike_margin_sd`` times this much.
        hypotheses: K; 1 plans on the estimate (unknown weights 0). K > 1 plans one
            action sequence on K networks sampled from the estimate
            (:meth:`ConnectivityEstimate.sample`) for the best mean return; measured
            worse than K = 1 on the training networks (docs/baselines.md), kept to
            reproduce that result.
        seed: seeds the hypotheses' draws (one draw per episode: ``seed`` and the
            number of episodes this policy has started); copies made by
            :meth:`spawn` (one per sub-environment of a vector environment) get
            ``seed + index``.
        probe: whether to probe when the plan misses wanted spikes.
        identification: ``"gaussian"`` (ridge regression, any n), ``"discrete"``
            (the exact posterior over {-1, 0, +1}, n <= 11; it knows more entries,
            docs/baselines.md compares the two) or
            ``"bayes"`` (that posterior under the observation model of ``extensions``,
            :mod:`spikectl.planning.bayes`; the Gaussian estimate above n = 11) or
            ``"particles"`` (the posterior over {-1, 0, +1} at any n, enumerated on the
            entries the evidence touched, the likeliest hypotheses of each column kept:
            :mod:`spikectl.planning.particles`).
        plan_on: what the planner takes for weights that are not known: ``"mean"``
            their posterior mean, ``"known"`` 0 (under measurement noise the mean is
            noisy), ``"auto"``: ``"mean"`` without measurement noise, ``"known"`` with
            it (docs/baselines.md measures the three).
        spike_margin_sd: spikes are read at the threshold less this many ``noise_mV``
            (the default was chosen on training networks at 1, 2 and 4 mV,
            docs/baselines.md).
        gamble_networks: K; 0 probes as described above. K > 0 chooses the action
            where the policy would probe by its expected return over K networks drawn
            from the estimate (QMDP). Off by default: on the paper's task it costs
            about 5x the CPU time for a gain within noise (docs/baselines.md).
        gamble_information: the bonus, in units of return per nat, for stimulating a
            ready neuron whose synapse onto the target is unknown (the entropy of that
            synapse over the K networks): QMDP alone values no information and waits
            (the default was chosen on validation networks, docs/baselines.md).
        gamble_horizon: steps each action is valued over, its own included.
        gamble_width: beam width of the best continuation on each drawn network.
        gamble_candidates: at most this many actions are valued (do nothing, the
            probe and the likeliest excitatory inputs of the target), for large n.
        known_weights: [n, n] the network's true signed weights (agent indexing): the
            same loop *told* the connectivity, with nothing left to identify (a
            privileged controller, near the oracle planner; a teacher for
            ``spikectl.training.learners.guided``).
        extensions: the environment's extensions, what ``identification="bayes"`` reads
            its observation model from (measurement noise, stochastic release,
            background input, synaptic spread; :class:`ObservationModel`); None: the
            paper's model with ``noise_mV``. With stochastic release, every
            identification learns from each spike's release chance. With
            heterogeneous neurons (and no measurement noise) the policy learns each
            neuron's threshold and leak (:class:`~spikectl.planning.heterogeneity.
            NeuronTracker`) and plans with them; with a synaptic spread it plans each
            known synapse at its estimated strength instead of its sign.
        filter_voltage: under measurement noise (``noise_mV`` > 0), plan from potentials
            filtered against the model's prediction (:class:`~spikectl.planning.
            filtering.FilteredState`) instead of the raw observations; where
            ``extensions`` leave the dynamics the paper's, the filter trusts the model's
            step exactly (:func:`~spikectl.planning.filtering.model_variance`).
        settle_releases: under stochastic release with exact residuals (no measurement
            noise, hidden or heterogeneous neurons, background input;
            :func:`~spikectl.planning.release.exact_residuals`), the Gaussian estimate
            learns from each spike's release settled from the next step's residuals
            (:func:`~spikectl.planning.release.settled_releases`) instead of its release
            chance; False: the chance, as before.
        unrested_inputs: under stochastic release, where the plan misses the next
            wanted spike, stimulate the target's known excitatory input with the highest
            release chance even before its vesicles are back by the paper's rule (the
            plan counts such an input as silent; it releases with its chance,
            :func:`~spikectl.planning.bayes.release_chances`). False: the plan's action.
        relays: with hidden neurons, learn each observed neuron's effect two steps after
            its release (through a hidden neuron it excites) beside G, and plan with it
            through a virtual relay neuron per observed neuron
            (:mod:`spikectl.planning.relays`); needs ``identification="gaussian"``.

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
        width: int = 32,
        horizon: int | None = 20,
        known_sd: float = 0.25,
        noise_mV: float = 0.0,
        hypotheses: int = 1,
        seed: int = 0,
        probe: bool = True,
        identification: str = "gaussian",
        plan_on: str = "auto",
        spike_margin_sd: float = 2.0,
        gamble_networks: int = 0,
        gamble_information: float = 0.03,
        gamble_horizon: int = 10,
        gamble_width: int = 8,
        gamble_candidates: int = 8,
        known_weights: np.ndarray | None = None,
        extensions: Extensions | None = None,
        filter_voltage: bool = False,
        settle_releases: bool = True,
        unrested_inputs: bool = True,
        relays: bool = False,
    ) -> None:
        params = NeuronParams() if params is None else params
        if not isinstance(params, NeuronParams):
            raise TypeError(f"params must be a NeuronParams, got {type(params).__name__}")
        if not isinstance(width, (int, np.integer)) or width < 1:
            raise ValueError(f"width must be an integer >= 1, got {width!r}")
        if horizon is not None and (not isinstance(horizon, (int, np.integer)) or horizon < 1):
            raise ValueError(f"horizon must be an integer >= 1 or None, got {horizon!r}")
        if not known_sd > 0:
            raise ValueError(f"known_sd must be > 0, got {known_sd!r}")
        if not noise_mV >= 0:
            raise ValueError(f"noise_mV must be >= 0, got {noise_mV!r}")
        if (
            not isinstance(hypotheses, (int, np.integer))
            or isinstance(hypotheses, bool)
            or (hypotheses < 1)
        ):
            raise ValueError(f"hypotheses must be an integer >= 1, got {hypotheses!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.hypotheses, self.seed, self.probe = int(hypotheses), int(seed), bool(probe)
        if identification not in IDENTIFICATIONS:
            raise ValueError(
                f"identification must be one of {', '.join(IDENTIFICATIONS)}, "
                f"got {identification!r}"
            )
        self.identification = identification
        if relays and identification != "gaussian":
            raise ValueError(f"relays=True needs identification='gaussian', got {identification!r}")
        self.relays = bool(relays)
        if plan_on not in ("auto", "mean", "known"):
            raise ValueError(f"plan_on must be 'auto', 'mean' or 'known', got {plan_on!r}")
        if not spike_margin_sd >= 0:
            raise ValueError(f"spike_margin_sd must be >= 0, got {spike_margin_sd!r}")
        self.plan_on, self.spike_margin_sd = plan_on, float(spike_margin_sd)
        for name, value, least in (("gamble_networks", gamble_networks, 0),
                                   ("gamble_horizon", gamble_horizon, 1),
                                   ("gamble_width", gamble_width, 1),
                                   ("gamble_candidates", gamble_candidates, 2)):  # fmt: skip
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
        if not gamble_information >= 0:
            raise ValueError(f"gamble_information must be >= 0, got {gamble_information!r}")
        self.gamble_networks, self.gamble_horizon = int(gamble_networks), int(gamble_horizon)
        self.gamble_width, self.gamble_candidates = int(gamble_width), int(gamble_candidates)
        self.gamble_information = float(gamble_information)
        if known_weights is not None:
            known_weights = np.asarray(known_weights)
            if known_weights.ndim != 2 or known_weights.shape[0] != known_weights.shape[1]:
                raise ValueError(
                    f"known_weights must be a square [n, n] array, got shape {known_weights.shape}"
                )
            if not np.isin(known_weights, (-1, 0, 1)).all():
                raise ValueError("known_weights must hold only -1, 0 and +1")
        self.known_weights = known_weights
        self.filter_voltage = bool(filter_voltage)
        if extensions is not None and not isinstance(extensions, Extensions):
            raise TypeError(f"extensions must be an Extensions, got {type(extensions).__name__}")
        self.extensions = extensions
        self._observation = ObservationModel.of(extensions, params)
        if extensions is None and noise_mV:
            self._observation = ObservationModel(noise_mV=float(noise_mV))
        # Stochastic release, told by ``extensions``: the evidence carries each spike's
        # release chance instead of the deterministic rule's release (the Bayes estimate
        # mixes over the releases; the Gaussian one regresses on the chances, or on the
        # releases settled from the residuals, below).
        self._release_chances = self._observation.stochastic_release
        # ... and where nothing else moves the potentials (no measurement noise, hidden
        # or heterogeneous neurons, background input), the residuals are exact integers
        # that tell which spikes released (:mod:`spikectl.planning.release`).
        self.settle_releases = bool(settle_releases)
        self.unrested_inputs = bool(unrested_inputs)
        self._settles_releases = (self._release_chances and self.settle_releases
                                  and not noise_mV and exact_residuals(extensions))  # fmt: skip
        # Synapses of different strengths (synaptic spread, told by ``extensions``): known
        # ones are planned at their estimated strength.
        self._strengths = extensions is not None and extensions.synaptic_spread > 0
        self.params, self.width, self.horizon = params, int(width), horizon
        self.known_sd, self.noise_mV = float(known_sd), float(noise_mV)
        # A plan is renewed when less than half its horizon is left, so that a wanted
        # spike just past its end is seen in time (a receding horizon).
        self._replan_margin = 1 if horizon is None else max(1, horizon // 2)
        self._residual_sd = residual_sd(params, noise_mV)
        self.reset()

    def reset(self) -> None:
        """Forget the episode (call at each episode's start; ``act`` at step 0 also does)."""
        self.estimate: ConnectivityEstimate | None = None
        self._tracker: ObservedState | None = None
        self._plan: Plan | None = None
        self._plan_start = 0
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
        self._uniforms: tuple[np.ndarray, np.ndarray] | None = None

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The action for this observation (an agent index, -1 for do nothing)."""
        check_controller_input(observation, info, "IdentifyAndPlan")
        step = int(observation["step"])
        voltage = np.asarray(observation["voltage"], dtype=np.float64)
        mask = np.asarray(info["action_mask"], dtype=bool)
        n = voltage.shape[0]
        if mask.shape != (n + 1,):
            raise ValueError(f"action_mask must have shape [{n + 1}], got {mask.shape}")
        if step == 0 or self._tracker is None:
            if step != 0:
                raise ValueError("IdentifyAndPlan must see the episode from its first step")
            self.reset()
            if tracks_neurons(self.extensions, self.noise_mV, self.params):
                self._tracker = NeuronTracker(n, self.params, self.extensions)
            elif self.filter_voltage and self.noise_mV > 0:
                self._tracker = FilteredState(n, self.params, self.noise_mV, self.spike_margin_sd,
                                              model_variance(self.extensions))  # fmt: skip
            else:
                self._tracker = ObservedState(n, self.params, self.spike_margin_sd * self.noise_mV)
            self.estimate = self._new_estimate(n)
            self._chances = np.zeros(n)
            draws = max(self.hypotheses if self.hypotheses > 1 else 0, self.gamble_networks)
            if draws:
                # One draw per episode, reused by every re-plan: hypotheses change only
                # where the estimate does (common random numbers).
                rng = np.random.default_rng([self.seed, self._episodes])
                self._uniforms = (rng.random((draws, n, n)), rng.random((draws, n)))
        else:
            since = self._tracker.state.steps_since_release[0].copy()
            if isinstance(self._tracker, FilteredState):
                evidence = self._tracker.observe(
                    voltage, int(observation["last_action"]), self.estimate.posterior()
                )
            else:
                evidence = self._tracker.observe(voltage, int(observation["last_action"]))
            if self._release_chances:
                evidence = self._release_evidence(*evidence[1:])
                self._chances = self._release_chances_after(self._tracker.spiked, since)
            self.estimate.add(*evidence)
        pattern = np.asarray(observation["pattern"], dtype=bool)
        if step >= pattern.shape[0]:
            raise ValueError(f"the episode has ended (step {step}): reset before acting")
        target = int(observation["target"])
        weights, known = self._planning_weights()
        surprised = self._predicted_spikes is not None and not np.array_equal(
            self._predicted_spikes, self._tracker.spiked
        )
        if (
            self._plan is None
            or surprised
            or not np.array_equal(weights, self._planned_weights)
            or not np.array_equal(self._neurons(), self._planned_neurons)
            or self._plan_remaining(step, pattern.shape[0]) < self._replan_margin
        ):
            self._replan(weights, target, mask, pattern, step)
        offset = step - self._plan_start
        action = int(self._plan.actions[offset])
        if self.probe and action == DO_NOTHING and self._misses_wanted_spikes(pattern, offset):
            if self.gamble_networks:
                action = self._gamble(known, target, mask, pattern, step)
            else:
                action = self._probe(known, target, mask)
        if self._release_chances and self.unrested_inputs:
            action = self._unrested_input(weights, known, target, mask, pattern, step, action)
        self._predict(weights, action)
        return action

    def _unrested_input(self, weights, known, target, mask, pattern, step, action) -> int:
        """Under stochastic release, where the plan does not hit the spike wanted at the
        next step: the target's known excitatory input (not refractory) with the
        highest release chance, which the plan's deterministic rule counts as silent
        until its vesicles are back; else ``action``."""
        offset = step - self._plan_start + 1  # the action reaches the target a step later
        if step + 1 >= pattern.shape[0] or not pattern[step + 1]:
            return action
        if offset < self._plan.rewards.shape[0] and self._plan.rewards[offset] > 0:
            return action
        state = self._tracker.state
        n = known.shape[0]  # weights also holds the relays where they are planned
        inputs = (known[:, target] & (weights[:n, target] > 0)
                  & (state.refractory_left[0] == 0) & mask[1:])  # fmt: skip
        if not inputs.any():
            return action
        # At the coming step; 0 where not an input.
        chance = self._release_chances_after(inputs, state.steps_since_release[0])
        return int(np.argmax(chance))

    def _release_chances_after(self, spiking: np.ndarray, since: np.ndarray) -> np.ndarray:
        """[n] the release chance of each ``spiking`` neuron one step after the tracked
        ``since`` steps since its last release (0 where not spiking)."""
        return release_chances(spiking, np.minimum(since + 1, SINCE_RELEASE_CAP), self.params)

    def _release_evidence(self, residual: np.ndarray, observed: np.ndarray) -> tuple:
        """Under stochastic release, the evidence of the last step's spikes: where the
        residuals are exact (:data:`_settles_releases`), each release settled from them
        (:func:`~spikectl.planning.release.settled_releases`) for the Gaussian
        estimate; otherwise each spike's release chance."""
        if (self._settles_releases and self._chances.any()
                and isinstance(self.estimate, ConnectivityEstimate)):  # fmt: skip
            excites, inhibits = self.estimate.entry_probabilities()
            return settled_releases(self._chances, residual, observed, excites, inhibits)
        return self._chances, residual, observed

    def _planning_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """(weights [n, n] to plan with, known [n, n]): known entries at their value;
        the others 0 (``plan_on="known"``) or their posterior mean (``"mean"``), which
        carries what is known of neurons that only ever released together (their
        summed effect) at 0.01 w_in resolution (so that tiny changes of the mean do
        not force a re-plan). Computed again only when the estimate has changed."""
        of = (id(self.estimate), self.estimate.version)  # reset() forgets it
        if of != self._weights_of:
            self._weights_cache = self._compute_planning_weights()
            self._weights_of = of
        return self._weights_cache

    def _compute_planning_weights(self) -> tuple[np.ndarray, np.ndarray]:
        weights, known = self._observed_planning_weights()
        if self._plans_relays:
            # [2n, 2n]: the observed neurons and their virtual relay neurons; known
            # stays [n, n] (what is known among the observed).
            weights = relay_weights(weights, self.estimate.relay_signs(self.known_sd))
        return weights, known

    def _observed_planning_weights(self) -> tuple[np.ndarray, np.ndarray]:
        signs, known = self.estimate.weights(self.known_sd)
        plan_on = self.plan_on
        if plan_on == "auto":
            plan_on = "mean" if self.noise_mV == 0 else "known"
        if plan_on == "known" and not self._strengths:
            return signs, known
        mean = np.round(self.estimate.posterior()[0], 2)
        if self._strengths:
            # Synapses differ in strength (synaptic spread): a known synapse is planned at
            # its estimated strength, not its sign.
            signs = np.where(known, mean, signs)
        if plan_on == "known":
            return signs, known
        return np.where(known, signs, mean), known

    def _neurons(self) -> np.ndarray | None:
        """[1, 2, m] per-neuron kernel parameters to plan with where the tracker has its
        own (:class:`~spikectl.planning.heterogeneity.NeuronTracker`: the neurons it
        learned; :class:`~spikectl.planning.filtering.FilteredState`: a threshold with a
        margin for the noise), the paper's for virtual relay neurons; else None (the
        paper's)."""
        if not isinstance(self._tracker, (NeuronTracker, FilteredState)):
            return None
        neurons = self._tracker.neurons()
        if self._plans_relays:
            relays = uniform_neuron_parameters(self.params, 1, neurons.shape[-1])
            neurons = np.ascontiguousarray(np.concatenate([neurons, relays], axis=-1))
        return neurons

    @property
    def _plans_relays(self) -> bool:
        """Whether the plan holds virtual relay neurons: ``relays`` asked for and the
        weights not told (told weights are the observed neurons' alone). The estimate
        (or what stands in for it) then answers ``relay_signs``."""
        return self.relays and self.known_weights is None

    def _planning_state(self):
        """The simulator state the plan starts from: the tracker's, with the virtual
        relay neurons' appended where the policy plans relays."""
        if self._plans_relays:
            return relay_state(self._tracker.state, self.params)
        return self._tracker.state

    def _new_estimate(self, n: int):
        if self.known_weights is not None:
            if self.known_weights.shape != (n, n):
                raise ValueError(
                    f"known_weights has shape {self.known_weights.shape}, but the "
                    f"observation has {n} neurons"
                )
            return KnownConnectivity(self.known_weights)
        if self.relays:
            return RelayConnectivityEstimate(n, self._residual_sd)
        if self.identification == "discrete":
            return DiscreteConnectivityEstimate(n, self._residual_sd)
        if self.identification == "particles":
            return ParticleConnectivityEstimate(n, self._residual_sd)
        if self.identification == "bayes" and column_hypotheses_fit(n):
            return BayesConnectivityEstimate(n, self._observation, self.params)
        return ConnectivityEstimate(n, self._residual_sd)

    def _replan(self, weights, target, mask, pattern, step) -> None:
        model = self._model(weights, target, mask)
        self._plan = beam_search(
            model, self._planning_state(), pattern, step, self.width, self.horizon
        )
        self._plan_start = step
        self._planned_weights = weights
        self._planned_neurons = model.neurons
        # Whether the plan misses a wanted spike from each of its steps on.
        wanted = pattern[step : step + self._plan.rewards.shape[0]]
        missing = wanted & (self._plan.rewards == 0)
        self._misses_from = np.logical_or.accumulate(missing[::-1])[::-1]
        self._model_cache = model
        self.replans += 1

    def _plan_remaining(self, step: int, episode_length: int) -> float:
        """Steps of the current plan still ahead of ``step`` (inf when it reaches the end)."""
        end = self._plan_start + self._plan.actions.shape[0]
        return np.inf if end >= episode_length else end - step

    def _model(self, weights, target, mask) -> PlanningModel:
        actions = (np.flatnonzero(mask) + DO_NOTHING).astype(np.int64)  # do nothing first
        if self.hypotheses > 1:
            uniforms = (self._uniforms[0][: self.hypotheses], self._uniforms[1][: self.hypotheses])
            hypotheses = self.estimate.sample(self.known_sd, *uniforms)  # [K, n, n]
            if self._plans_relays:
                relays = self.estimate.relay_signs(self.known_sd)
                hypotheses = np.stack([relay_weights(drawn, relays) for drawn in hypotheses])
            return PlanningModel(hypotheses, target, actions, self.params, self._neurons())
        return PlanningModel(weights[None].copy(), target, actions, self.params, self._neurons())

    def _misses_wanted_spikes(self, pattern: np.ndarray, offset: int) -> bool:
        """True when the current plan does not hit every wanted spike still ahead
        (the pattern is the episode's, the one the plan was made for)."""
        return bool(self._misses_from[offset])

    def _ready(self) -> np.ndarray:
        """[n] neurons that release if they spike now (not refractory, vesicles back)."""
        state = self._tracker.state
        return (state.refractory_left[0] == 0) & (
            state.steps_since_release[0] >= self.params.min_release_interval_steps
        )

    def _probe(self, known: np.ndarray, target: int, mask: np.ndarray, count: bool = True) -> int:
        """The ready neuron with unknown outgoing weights most likely to excite the
        target (measured on the training contexts: better than saving the likely ones
        for the steps before wanted spikes), or do nothing when there is none."""
        ready = self._ready()
        unknown_row = ~known.all(axis=1)
        candidates = ready & unknown_row & mask[1:]
        if not candidates.any():
            return DO_NOTHING
        score = self.estimate.excitation_probability(target, self.known_sd)
        score = score + 1e-3 * (~known).sum(axis=1)  # then the row that teaches most
        score[~candidates] = -np.inf
        self.probes += count
        return int(np.argmax(score))

    def _gamble(self, known, target, mask, pattern, step) -> int:
        """The action of highest expected return over K networks drawn from the
        estimate, plus the information bonus (:func:`qmdp_action`)."""
        probe = self._probe(known, target, mask, count=False)
        uniforms = (draws[: self.gamble_networks] for draws in self._uniforms)
        action = qmdp_action(
            self.estimate.sample(self.known_sd, *uniforms),
            self.estimate.excitation_probability(target, self.known_sd), self._tracker.state,
            self._ready(), known[:, target], probe, (np.flatnonzero(mask) + DO_NOTHING),
            pattern, step, target, self.params, horizon=self.gamble_horizon,
            width=self.gamble_width, information=self.gamble_information,
            max_candidates=self.gamble_candidates,
        )  # fmt: skip
        self.probes += action != DO_NOTHING
        self.gambles += 1
        return action

    def _predict(self, weights: np.ndarray, action: int) -> None:
        """The spikes the estimate predicts for the coming step (to detect surprises)."""
        state = self._planning_state().copy()
        m = weights.shape[0]  # the observed neurons, and their relays where planned
        voltage, spikes = np.empty((1, 1, m)), np.empty((1, 1, m), dtype=bool)
        actions = np.array([[action]], dtype=np.int64)
        advance(state, np.ascontiguousarray(weights[None]), actions, self.params, voltage, spikes,
                self._neurons())  # fmt: skip
        self._predicted_spikes = spikes[0, 0, : self._tracker.spiked.shape[0]]

    def spawn(self, index: int) -> IdentifyAndPlan:
        """A fresh copy with the same settings, seeded ``seed + index``: what
        :func:`spikectl.envs.controller.batched` plays in sub-environment ``index``."""
        settings = {name: getattr(self, name) for name in _SETTINGS}
        return IdentifyAndPlan(self.params, **{**settings, "seed": self.seed + index})
