"""The potentials under measurement noise, filtered by the model (a per-neuron Kalman filter).

:class:`~spikectl.planning.identify.ObservedState` takes a noisy observation as the
potential it plans from. Under 2 mV of noise that moves a resting neuron (exactly at V_r
in the model) by 2 mV either way, and one excitatory synapse from rest lands exactly on
the threshold: the planner's start state decides spikes by the noise. The model knows
more than the observation: a neuron that spiked is at V_r, one that was held refractory
too, and between spikes a potential follows the kernel's Euler step from the last one
plus the synaptic input, which the posterior over G predicts (its mean, with its
variance). :class:`FilteredState` combines that prediction (mean m, variance P) with
the observation (variance sigma^2) per neuron,

    V = m + K (V_obs - m),   K = P / (P + sigma^2),   P <- (1 - K) P,

and reads a spike where the filtered potential is within ``spike_margin_sd`` posterior
standard deviations of the threshold. The paper's dynamics are deterministic, so there
the prediction's only variance is the synapses' (:func:`model_variance`): told the
weights, the filter reproduces the potentials exactly whatever the noise. The residuals
the identification learns from are what they were (the observation against the
no-synapse step from the last potential).
"""

from __future__ import annotations

import numpy as np

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.kernel import integrate
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import neuron_parameters
from spikectl.planning import portable
from spikectl.planning.identify import ObservedState

MODEL_VARIANCE_MV2 = 0.25
"""Variance (mV^2) the prediction of one step is given beyond the synapses' where the
environment's dynamics are not the paper's (:func:`model_variance`): what the model does
not know of them, so that the filter never trusts it absolutely."""


def model_variance(extensions: Extensions | None) -> float:
    """The variance (mV^2) :class:`FilteredState` adds to each step's prediction in an
    environment with ``extensions``: 0 where the dynamics are the paper's (at most the
    observation changes: measurement noise, bleaching), which are deterministic, so that
    the prediction is exact once the weights are (a neuron at rest stays exactly at
    V_r, one excitatory release from rest lands exactly on the threshold; any variance
    would let the noise move both); :data:`MODEL_VARIANCE_MV2` where hidden or
    heterogeneous neurons, stochastic release or background input make the model's step
    wrong or random."""
    if extensions is None:
        return 0.0
    unmodelled = (extensions.hidden_neurons > 0 or extensions.hidden_fraction > 0
                  or extensions.heterogeneous or extensions.random_dynamics)  # fmt: skip
    return MODEL_VARIANCE_MV2 if unmodelled else 0.0


class FilteredState(ObservedState):
    """:class:`ObservedState` with potentials filtered against the model's prediction.

    Args:
        n_neurons, params: as :class:`ObservedState`.
        noise_mV: sigma of the measurement noise (> 0).
        spike_margin_sd: a spike is read where the filtered potential is at least the
            threshold less this many posterior standard deviations.
        model_variance_mV2: the variance added to each step's prediction beyond the
            synapses' (:func:`model_variance` of the environment's extensions).
    """

    def __init__(self, n_neurons: int, params: NeuronParams, noise_mV: float,
                 spike_margin_sd: float, model_variance_mV2: float = MODEL_VARIANCE_MV2,
                 ) -> None:  # fmt: skip
        if not noise_mV > 0:
            raise ValueError(f"noise_mV must be > 0 to filter, got {noise_mV!r}")
        if not model_variance_mV2 >= 0:
            raise ValueError(f"model_variance_mV2 must be >= 0, got {model_variance_mV2!r}")
        self.model_variance_mV2 = float(model_variance_mV2)
        super().__init__(n_neurons, params, 0.0)
        self.noise_variance = float(noise_mV) ** 2
        self.spike_margin_sd = float(spike_margin_sd)
        self.variance = np.zeros(n_neurons)  # at rest: exactly V_r
        self.filtered = np.full(n_neurons, params.v_rest_mV)
        # The neurons the planner simulates from the filtered potentials: the paper's,
        # spiking from spike_margin_sd * noise_mV below the threshold (see neurons()).
        thresholds = np.full((1, n_neurons), params.v_threshold_mV - spike_margin_sd * noise_mV)
        time_constants = np.full((1, n_neurons), params.membrane_time_constant_ms)
        self._planning = neuron_parameters(params, thresholds, time_constants)

    def neurons(self) -> np.ndarray:
        """[1, 2, n] kernel parameters to plan with: the paper's neurons, but spiking from
        ``spike_margin_sd`` times the noise below the threshold. One release from rest
        lands a neuron exactly on the threshold; a filtered potential a fraction of a mV
        below rest (where unknown weights left the filter unsure) would make the planner
        expect no spike from it and give up on wanted spikes it can hit (measured in
        docs/baselines.md)."""
        return self._planning

    def observe(self, voltage, action, weights=None):
        """As :meth:`ObservedState.observe`; ``weights`` = (mean [n, n], sd [n, n]) of G
        (units of w_in) predicts the synaptic input (None: no synapses known)."""
        state, params = self.state, self.params
        voltage = np.asarray(voltage, dtype=np.float64)
        before = state.voltage_mV[0].copy()
        refractory = state.refractory_left[0] > 0
        released = state.released[0].astype(np.float64)
        drive = np.zeros_like(before)
        input_variance = np.zeros_like(before)
        if weights is not None:
            mean, sd = weights
            drive = params.synaptic_step_mV * portable.matmul(released, mean)
            input_variance = params.synaptic_step_mV**2 * portable.matmul(released, sd**2)
        if action >= 0:
            drive[action] += params.stimulus_step_mV
        predicted = integrate(before, params.v_rest_mV, params.leak_per_step, drive)
        prior = (1.0 - params.leak_per_step) ** 2 * self.variance + input_variance
        prior = prior + self.model_variance_mV2
        gain = prior / (prior + self.noise_variance)
        filtered = predicted + gain * (voltage - predicted)
        posterior = (1.0 - gain) * prior
        threshold = params.v_spike_mV - self.spike_margin_sd * np.sqrt(posterior)
        # The base class reads spikes and sets the state from the potentials it is given:
        # give it the filtered ones, against the threshold less the margin.
        self._threshold = threshold
        evidence = super().observe(filtered, action)
        # Its residual compares the filtered potential; the identification's is the raw
        # observation against the no-synapse step from the last potential.
        stimulus = np.zeros_like(before)
        if action >= 0:
            stimulus[action] = params.stimulus_step_mV
        silent = integrate(before, params.v_rest_mV, params.leak_per_step, stimulus)
        residual = (voltage - silent) / params.synaptic_step_mV
        reset = self.spiked | refractory
        self.variance = np.where(reset, 0.0, posterior)
        self.filtered = filtered
        return evidence[0], residual, evidence[2]
