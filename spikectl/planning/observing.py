"""Identify-and-plan's observation part: how an observation becomes evidence about G and
the simulator state the planner starts from.

On the paper's model a spike is read at the threshold and each residual over 20 mV is a
linear equation in a column of G (:class:`~spikectl.planning.identify.ObservedState`).
The task's own observation model changes that where the composition reads it
(``task_model``): under measurement noise spikes are read below the threshold, or from
potentials filtered against the model (``filter_voltage``,
:class:`~spikectl.planning.filtering.FilteredState`); with heterogeneous neurons each
neuron's threshold and leak are learned (:class:`~spikectl.planning.heterogeneity.
NeuronTracker`); under stochastic release each spike's release is read back from the next
step's residuals where they are exact (:func:`~spikectl.planning.release.
settled_releases`), else it enters at its release chance; with a synaptic spread known
synapses are planned at their estimated strength. Under loop latency each step is read
with the stimulation that landed at it (:class:`~spikectl.planning.in_flight.InFlight`).
Under spikes-only sensing the spikes are read by :class:`~spikectl.planning.spike_filter.
SpikeState`, whose potentials are the spike filter's (the ``"spikes"`` estimator); where
the composition reads the task's model, by :class:`~spikectl.planning.spike_likelihood.
SpikeLikelihoodState`, under background input and the ChR2 light (the
``"spike-likelihood"`` estimator).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.kernel import SINCE_RELEASE_CAP
from spikectl.neuron.opsin import OpsinActuator
from spikectl.neuron.params import NeuronParams
from spikectl.planning.bayes import ObservationModel, release_chances
from spikectl.planning.filtering import FilteredState, model_variance
from spikectl.planning.heterogeneity import NeuronTracker, tracks_neurons
from spikectl.planning.identify import ObservedState, residual_sd
from spikectl.planning.in_flight import InFlight
from spikectl.planning.lit_search import planned_light
from spikectl.planning.release import exact_residuals, settled_releases
from spikectl.planning.spike_filter import SpikeState
from spikectl.planning.spike_likelihood import SpikeLikelihoodState


@dataclass(frozen=True)
class ObservationSettings:
    """The observation part's settings.

    Attributes:
        task_model: read the environment's extensions as the observation model
            (stochastic release, heterogeneous neurons, synaptic spread, and the
            likelihood of the ``"bayes"`` estimator); False: the paper's model with the
            environment's measurement noise alone.
        filter_voltage: under measurement noise, plan from potentials filtered against
            the model's prediction instead of the raw observations.
        spike_margin_sd: under measurement noise, spikes are read this many noise
            standard deviations below the threshold (chosen on training networks at 1,
            2 and 4 mV, docs/baselines.md).
    """

    task_model: bool = False
    filter_voltage: bool = False
    spike_margin_sd: float = 2.0

    def __post_init__(self) -> None:
        if isinstance(self.spike_margin_sd, bool) or not self.spike_margin_sd >= 0:
            raise ValueError(f"spike_margin_sd must be >= 0, got {self.spike_margin_sd!r}")

    def bind(self, params: NeuronParams, extensions: Extensions | None) -> Observation:
        """This part on an environment with ``extensions`` (None: the paper's)."""
        return Observation(self, params, extensions)

    def settles_releases(self, extensions: Extensions | None, noise_mV: float) -> bool:
        """Whether each release of a stochastic one is settled from the next step's
        residuals: where they are exact integers (no measurement noise, hidden or
        heterogeneous neurons, background input; :func:`~spikectl.planning.release.
        exact_residuals`). On the ``stochastic`` sets +0.013 network by network
        against the release chance (docs/results/release-settling)."""
        return not noise_mV and exact_residuals(extensions)


class Observation:
    """The observation part bound to an environment: what the estimate and the planner
    are told of the task.

    Attributes:
        noise_mV: the environment's measurement noise (0: none).
        extensions: the extensions read as the observation model (None: the paper's).
        model: the likelihood the ``"bayes"`` estimator reads.
        residual_sd: the residual noise (units of w_in) the Gaussian estimates assume.
        stochastic_release: spikes release by chance (the evidence carries chances).
        strengths: synapses differ in strength (known ones planned at their estimate).
    """

    def __init__(self, settings: ObservationSettings, params: NeuronParams,
                 extensions: Extensions | None) -> None:  # fmt: skip
        if extensions is not None and not isinstance(extensions, Extensions):
            raise TypeError(f"extensions must be an Extensions, got {type(extensions).__name__}")
        self.settings, self.params = settings, params
        self.noise_mV = 0.0 if extensions is None else float(extensions.observation_noise_mV)
        self.extensions = extensions if settings.task_model else None
        self.model = ObservationModel.of(self.extensions, params)
        if self.extensions is None and self.noise_mV:
            self.model = ObservationModel(noise_mV=self.noise_mV)
        self.residual_sd = residual_sd(params, self.noise_mV)
        self.stochastic_release = self.model.stochastic_release
        self.settles = self.stochastic_release and settings.settles_releases(
            self.extensions, self.noise_mV
        )
        self.strengths = self.extensions is not None and self.extensions.synaptic_spread > 0
        # The actuator and the sensing are part of the loop whatever the composition
        # reads (ChR2's light; spikes in place of potentials).
        self.light_mW_per_mm2 = planned_light(extensions)
        self.spikes_only = extensions is not None and extensions.spikes_only
        if self.spikes_only:
            # Reading the task's model, the spikes are weighed under its background input
            # and light (:mod:`~spikectl.planning.spike_likelihood`).
            _check_spike_sensing(extensions, under_rig=settings.task_model)
        elif self.light_mW_per_mm2 is not None and self._filters_or_tracks_neurons:
            raise ValueError(
                "the ChR2 actuator is read by the paper's tracker alone "
                "(no noise, heterogeneous neurons or filtering)"
            )

    @property
    def _filters_or_tracks_neurons(self) -> bool:
        """Whether the reader's tracker is another than the paper's (each neuron's
        threshold and leak learned, or potentials filtered under noise)."""
        noise = self.noise_mV
        return (tracks_neurons(self.extensions, noise, self.params)
                or (self.settings.filter_voltage and noise > 0))  # fmt: skip

    @property
    def plan_mean(self) -> bool:
        """Whether unknown weights are planned at their posterior mean (without noise)
        rather than 0 (under noise that mean is noisy)."""
        return self.noise_mV == 0

    def reader(self, n: int, latency_steps: int = 0) -> Reader:
        """A fresh reader for an episode on ``n`` observed neurons in a loop of
        ``latency_steps`` steps of latency."""
        settings, params, noise = self.settings, self.params, self.noise_mV
        if self.spikes_only and not settings.task_model:  # the exact filter's spikes
            return Reader(self, SpikeState(n, params, 0.0), InFlight(latency_steps, n))
        if self.spikes_only:  # weighed under the task's background input and light
            reader = Reader(self, SpikeLikelihoodState(n, params, 0.0), InFlight(latency_steps, n))
            if self.light_mW_per_mm2 is not None:
                reader.opsin = OpsinActuator(1, n, self.light_mW_per_mm2, params.dt_ms,
                                             params.capacitance_pF)  # fmt: skip
            return reader
        if tracks_neurons(self.extensions, noise, params):
            tracker = NeuronTracker(n, params, self.extensions)
        elif settings.filter_voltage and noise > 0:
            tracker = FilteredState(n, params, noise, settings.spike_margin_sd,
                                    model_variance(self.extensions))  # fmt: skip
        else:
            tracker = ObservedState(n, params, settings.spike_margin_sd * noise)
        reader = Reader(self, tracker, InFlight(latency_steps, n))
        if self.light_mW_per_mm2 is not None:  # the paper's tracker (checked when bound)
            reader.opsin = OpsinActuator(1, n, self.light_mW_per_mm2, params.dt_ms,
                                         params.capacitance_pF)  # fmt: skip
        return reader


class Reader:
    """One episode's observations read into evidence and the tracked simulator state.

    Attributes:
        tracker: the tracked state (``tracker.state``, ``tracker.spiked``).
        chances: [n] each spike's release chance at the last step (stochastic release;
            zeros otherwise).
        in_flight: the loop's actions in flight (:class:`~spikectl.planning.in_flight.
            InFlight`): under latency a step's evidence is read with the action that
            landed at it, not the one chosen then.
        opsin: under the ChR2 actuator, the opsins' occupancies tracked from the light
            that landed (they depend on it alone); each step is read with their current,
            computed from them and the tracked potentials. None for the pulse.
    """

    def __init__(self, observation: Observation, tracker: ObservedState,
                 in_flight: InFlight | None = None) -> None:  # fmt: skip
        self.observation, self.tracker = observation, tracker
        self.chances = np.zeros(tracker.spiked.shape[0])
        self.in_flight = InFlight(0, tracker.spiked.shape[0]) if in_flight is None else in_flight
        self.opsin: OpsinActuator | None = None

    def read_landed(self, observation, voltage: np.ndarray, estimate) -> tuple:
        """:meth:`read` of ``voltage`` with the action that landed at the step before
        ``observation`` (its ``last_action`` without latency)."""
        return self.read(voltage, self.in_flight.landed(observation), estimate)

    def read(self, voltage: np.ndarray, action: int, estimate) -> tuple:
        """The evidence of the observation after a step with ``action``
        (``estimate.add``'s arguments); advances the tracked state."""
        tracker = self.tracker
        since = tracker.state.steps_since_release[0].copy()
        if isinstance(tracker, FilteredState):
            evidence = tracker.observe(voltage, action, estimate.posterior())
        elif isinstance(tracker, SpikeLikelihoodState):  # the light's occupancies advance
            evidence = tracker.observe(voltage, action, self.opsin)
        elif self.opsin is not None:  # the light's current, as the environment drew it
            drive = np.empty((1, 1, tracker.spiked.shape[0]))
            self.opsin.illuminate(tracker.state.voltage_mV, np.array([[action]]), drive)
            evidence = tracker.observe(voltage, action, drive[0, 0])
        else:
            evidence = tracker.observe(voltage, action)
        if self.observation.stochastic_release:
            evidence = self.release_evidence(estimate, *evidence[1:])
            self.chances = self.chances_after(tracker.spiked, since)
        return evidence

    def release_evidence(self, estimate, residual: np.ndarray, observed: np.ndarray) -> tuple:
        """Under stochastic release, the evidence of the last step's spikes: each release
        settled from the residuals where they are exact, for an estimate that answers
        ``entry_probabilities`` (the Gaussian ones: the settling weighs each combination
        of releases by them); otherwise each spike's release chance."""
        if (self.observation.settles and self.chances.any()
                and hasattr(estimate, "entry_probabilities")):  # fmt: skip
            excites, inhibits = estimate.entry_probabilities()
            return settled_releases(self.chances, residual, observed, excites, inhibits)
        return self.chances, residual, observed

    def chances_after(self, spiking: np.ndarray, since: np.ndarray) -> np.ndarray:
        """[n] the release chance of each ``spiking`` neuron one step after ``since``
        steps since its last release (0 where not spiking)."""
        since = np.minimum(since + 1, SINCE_RELEASE_CAP)
        return release_chances(spiking, since, self.observation.params)

    def settle(self, estimate) -> None:
        """After ``estimate`` took the step's evidence: a tracker whose potentials are the
        estimate's (spikes-only sensing) takes them; the others keep what they read."""
        if isinstance(self.tracker, SpikeState):
            self.tracker.follow(estimate)

    def neurons(self) -> np.ndarray | None:
        """[1, 2, n] per-neuron kernel parameters to plan with where the tracker has its
        own (learned neurons; a threshold with a margin for the noise), else None (the
        paper's)."""
        if isinstance(self.tracker, (NeuronTracker, FilteredState)):
            return self.tracker.neurons()
        return None


_SPIKE_FILTER_OFF = ("hidden_neurons", "hidden_fraction", "threshold_spread",
                     "time_constant_spread", "synaptic_spread", "stochastic_release",
                     "background_rate", "recorded_neurons")  # fmt: skip
"""The extension fields the spike filter cannot read spikes under: its columns imply the
potentials of the paper's deterministic model of the observed neurons alone, every one
of them recorded."""


_SPIKE_LIKELIHOOD_READS = ("background_rate",)
"""What the spike likelihood (the task's model read, :mod:`~spikectl.planning.
spike_likelihood`) reads beyond the exact filter: background input (and the ChR2 light)."""


def _check_spike_sensing(extensions: Extensions, under_rig: bool = False) -> None:
    """Refuse, in one line, what spikes-only identification cannot read (``under_rig``:
    the spike likelihood's, which reads background input and the ChR2 light)."""
    reads = _SPIKE_LIKELIHOOD_READS if under_rig else ()
    on = [name for name in _SPIKE_FILTER_OFF if getattr(extensions, name) and name not in reads]
    if extensions.lit and not under_rig:
        on.append(f"actuator={extensions.actuator!r}")
    if under_rig and extensions.background_rate and extensions.background_current_pA < 0:
        on.append("a hyperpolarising background_current_pA")
    if on:
        model = ("under background input and the ChR2 light" if under_rig else
                 "on the paper's deterministic model with the current pulse")  # fmt: skip
        raise ValueError(
            f"identify-and-plan reads spikes-only sensing {model}; it cannot with {', '.join(on)}"
        )
