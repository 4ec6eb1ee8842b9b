"""Identify the hidden connectivity from observed potentials (the model is public, G is not).

With the paper's noise-free model, a neuron j that was not refractory at step t
obeys, exactly (docs/model.md):

    V_obs,j(t) = V_j(t-1) - (V_j(t-1) - V_r) dt/(RC) + 40 mV [a_t = j]
                 + 20 mV * sum_i G[i, j] released_i(t-1)

where V_j(t-1) is the potential after the reset of step t-1 (V_r if j spiked, else
the observation), and ``released_i(t-1)`` follows from i's observed spikes and the
vesicle rule. So each residual, divided by 20 mV, is a linear equation in column j
of G with integer right-hand side. :class:`ConnectivityEstimate` keeps one Gaussian
posterior per column (ridge regression with the topology's connection probabilities
as prior variances): noise-free and with every release seen alone, its mean is the
exact weight and its standard deviation near zero; a presynaptic neuron that never
released keeps its prior (the uncertainty). Measurement noise, hidden neurons,
stochastic release, heterogeneous neurons and background input all enter as extra
residual noise: the estimate degrades, it does not break.

:class:`ObservedState` turns the observations into the simulator state the planner
starts from.
"""

from __future__ import annotations

from math import erfc as _erfc

import numba
import numpy as np

from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.neuron.kernel import SINCE_RELEASE_CAP, integrate
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState
from spikectl.planning import portable

erfc = np.vectorize(_erfc, otypes=[np.float64])

# Residual noise (in units of w_in) assumed without measurement noise: float32
# observations round potentials at ~1e-6 mV, so this is loose and still makes one
# clean observation decisive against a prior variance of at most 0.3.
NOISE_FREE_SD = 0.01


def residual_sd(params: NeuronParams, noise_mV: float) -> float:
    """The residual noise (in units of w_in) of one observation under Gaussian measurement
    noise of ``noise_mV``: a residual differences two noisy observations, the older one
    shrunk by the leak; at least :data:`NOISE_FREE_SD`."""
    noise_sd = noise_mV * np.hypot(1.0, 1.0 - params.leak_per_step) / params.synaptic_step_mV
    return max(float(noise_sd), NOISE_FREE_SD)


def synapse_probabilities(mean: np.ndarray, sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P(w > 1/2), P(w < -1/2)) for w ~ N(mean, sd²) in units of w_in: that the rounded
    weight is an excitatory synapse, an inhibitory one."""
    scale = sd * np.sqrt(2.0)
    return 0.5 * erfc((0.5 - mean) / scale), 0.5 * erfc((0.5 + mean) / scale)


class ConnectivityEstimate:
    """Gaussian posterior over the signed weights G [n, n] in units of w_in.

    Column j has precision ``prior + X^T X / s^2`` and mean ``precision^-1 X^T y / s^2``
    (prior mean 0), where the rows of X are the release vectors of the steps before
    each observation of j and y the residuals over 20 mV.
    """

    # The prior of each size and its posterior: (prior variance, precision, (mean, sd)),
    # computed once (a controller starts an estimate every episode; issue 24).
    _PRIORS: dict[int, tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]] = {}

    def __init__(self, n_neurons: int, residual_sd: float) -> None:
        if residual_sd <= 0:
            raise ValueError(f"residual_sd must be > 0, got {residual_sd}")
        n = n_neurons
        self.n_neurons = n
        self._noise_precision = 1.0 / residual_sd**2
        self.moment = np.zeros((n, n))  # [post j, pre]
        self.observations = 0
        self.version = 0
        """Counts the changes of the posterior (what may be cached against it)."""
        self._weights: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._parts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        prior = self._PRIORS.get(n)
        if prior is None:
            index = np.arange(n)
            prior_variance = connection_probability(np.abs(index[:, None] - index[None, :]))
            np.fill_diagonal(prior_variance, 1e-9)  # no self-connections
            self.prior_variance = prior_variance  # [n (pre), n (post)]
            self.precision = np.zeros((n, n, n))  # [post j, pre, pre]
            self.precision[:, index, index] = (1.0 / prior_variance).T
            self._cache: tuple[np.ndarray, np.ndarray] | None = None
            prior = (prior_variance.copy(), self.precision.copy(), self.posterior())
            self._PRIORS[n] = prior
        self.prior_variance = prior[0].copy()
        self.precision = prior[1].copy()
        self._cache = (prior[2][0].copy(), prior[2][1].copy())

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """One step's evidence: ``released`` [n] (0/1, or release probabilities) of the
        previous step, ``residual`` [n] in units of w_in, ``observed`` [n] bool columns."""
        if not observed.any() or not np.any(released):
            return
        add_evidence(self.precision, self.moment, observed, released, residual,
                     self._noise_precision)  # fmt: skip
        self.observations += int(observed.sum())
        self.version += 1
        self._cache = None
        self._parts = None
        self._weights.clear()

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of G, both [n (pre), n (post)]."""
        if self._cache is None:
            mean, sd = portable.gaussian_posterior(self.precision, self.moment)  # [post, pre]
            self._cache = (mean.T.copy(), sd.T.copy())
        return self._cache

    def weights(self, known_sd: float) -> tuple[np.ndarray, np.ndarray]:
        """(signed weights [n, n] in {-1, 0, +1} to plan with, known [n, n] bool).

        An entry is known when its posterior standard deviation is below ``known_sd``;
        known entries are the rounded mean, unknown ones 0 (the prior's most likely
        value: no connection). Rows follow Dale's law: once a row's known nonzero
        entries agree on a sign, entries of the other sign are dropped.
        """
        cached = self._weights.get(known_sd)
        if cached is not None:
            return cached
        mean, sd = self.posterior()
        signs, known = np.empty(mean.shape, dtype=np.int8), np.empty(mean.shape, dtype=bool)
        _planned_signs(mean, sd, float(known_sd), signs, known)
        result = self._weights[known_sd] = (signs, known)
        return result

    def sample(
        self, known_sd: float, connection_uniforms: np.ndarray, sign_uniforms: np.ndarray
    ) -> np.ndarray:
        """K hypotheses int8 [K, n, n] about G: known entries as in :meth:`weights`, the
        others drawn from what is known of them, by the uniforms given.

        An unknown entry the evidence has not touched (posterior sd still at least 0.9
        of the prior's) is a connection with the topology's probability for its
        distance; one the evidence has narrowed, with probability P(|w| > 1/2) under
        its Gaussian posterior. A connection's sign is its row's (Dale's law) when the
        row has a known nonzero entry, else excitatory with probability 0.8.

        Args:
            known_sd: as in :meth:`weights`.
            connection_uniforms: [K, n, n] uniforms in [0, 1), one per hypothesis and entry.
            sign_uniforms: [K, n] uniforms in [0, 1), one per hypothesis and row.
        """
        signs, known = self.weights(known_sd)
        excites, inhibits, untouched = self._synapse_parts()
        tail = excites + inhibits  # P(|w| > 1/2): the rounded weight is nonzero
        probability = np.where(untouched, self.prior_variance, tail)  # [n, n]
        probability = np.where(known, 0.0, probability)
        row_sign = np.sign(signs.sum(axis=1))  # [n]
        drawn_sign = np.where(sign_uniforms < EXCITATORY_PROBABILITY, 1, -1)  # [K, n]
        sign = np.where(row_sign != 0, row_sign, drawn_sign)[:, :, None]  # [K, n, 1]
        connected = connection_uniforms < probability  # [K, n, n]
        hypotheses = np.where(known, signs, np.where(connected, sign, 0))
        return np.ascontiguousarray(hypotheses, dtype=np.int8)

    def entry_probabilities(self) -> tuple[np.ndarray, np.ndarray]:
        """(P(G = +1), P(G = -1)), both [n (pre), n (post)]: for an entry the evidence
        has not touched (posterior sd still at least 0.9 of the prior's) the topology's
        connection probability for its distance, excitatory with probability 0.8; for
        one it has narrowed, P(w > 1/2) and P(w < -1/2) under its Gaussian posterior."""
        excites, inhibits, untouched = self._synapse_parts()
        prior = self.prior_variance
        return (np.where(untouched, prior * EXCITATORY_PROBABILITY, excites),
                np.where(untouched, prior * (1.0 - EXCITATORY_PROBABILITY), inhibits))  # fmt: skip

    def _synapse_parts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(P(w > 1/2), P(w < -1/2), untouched), each [n (pre), n (post)], under the
        Gaussian posterior; untouched where its sd is still at least 0.9 of the prior's.
        What :meth:`sample` and :meth:`entry_probabilities` read, kept until the
        posterior changes (the acting loop asks every step with a spike)."""
        if self._parts is None:
            mean, sd = self.posterior()
            excites, inhibits = synapse_probabilities(mean, sd)
            self._parts = (excites, inhibits, sd >= 0.9 * np.sqrt(self.prior_variance))
        return self._parts

    def excitation_probability(self, target: int, known_sd: float) -> np.ndarray:
        """[n] probability that neuron i excites ``target`` (1/0 where known, else prior)."""
        weights, known = self.weights(known_sd)
        prior = self.prior_variance[:, target] * EXCITATORY_PROBABILITY
        return np.where(known[:, target], (weights[:, target] > 0).astype(float), prior)


def _planned_signs(mean, sd, known_sd, signs, known):
    """:meth:`ConnectivityEstimate.weights` into ``signs`` (int8) and ``known`` (bool),
    each [n, n]: known where sd < known_sd, there the rounded mean clipped to [-1, 1];
    then per row (Dale's law) the entries against the sign of the row's sum dropped.
    Every step is exact (comparisons, rounding, sums of -1, 0 and 1)."""
    rows, columns = mean.shape
    for i in range(rows):
        total = 0
        for j in range(columns):
            known[i, j] = sd[i, j] < known_sd
            value = 0
            if known[i, j]:
                value = int(min(max(np.rint(mean[i, j]), -1.0), 1.0))
            signs[i, j] = value
            total += value
        row_sign = (total > 0) - (total < 0)
        if row_sign != 0:
            for j in range(columns):
                if signs[i, j] != row_sign:
                    signs[i, j] = 0


_planned_signs = numba.njit(cache=True, nogil=True)(_planned_signs)


def _add_evidence(precision, moment, observed, regressors, residual, weight):
    """precision[j] += outer(regressors, regressors) * weight and moment[j] += residual[j]
    * regressors * weight for each observed column j, in place: NumPy's products in
    NumPy's order (the same bits), without its temporaries (called at every step with a
    release)."""
    size = regressors.shape[0]
    for j in range(precision.shape[0]):
        if not observed[j]:
            continue
        for a in range(size):
            for b in range(size):
                precision[j, a, b] += regressors[a] * regressors[b] * weight
            moment[j, a] += residual[j] * regressors[a] * weight


_add_evidence = numba.njit(cache=True, nogil=True)(_add_evidence)


def add_evidence(precision: np.ndarray, moment: np.ndarray, observed: np.ndarray,
                 regressors: np.ndarray, residual: np.ndarray, weight: float) -> None:  # fmt: skip
    """One step's evidence on the Gaussian columns, in place: for each ``observed`` [n]
    column j, ``precision[j]`` [m, m] += the regressors' [m] outer product times
    ``weight`` (the noise precision), ``moment[j]`` [m] += ``residual[j]`` times the
    regressors times ``weight``."""
    _add_evidence(precision, moment, np.ascontiguousarray(observed, dtype=np.bool_),
                  np.ascontiguousarray(regressors, dtype=np.float64),
                  np.ascontiguousarray(residual, dtype=np.float64), float(weight))  # fmt: skip


class KnownConnectivity:
    """Stands in for :class:`ConnectivityEstimate` where the weights are told (a
    privileged controller: the same loop with nothing left to identify): every entry
    known and right, whatever is observed."""

    def __init__(self, weights: np.ndarray) -> None:
        self._weights = np.asarray(weights, dtype=np.int8)
        self.n_neurons = self._weights.shape[0]
        self.version = 0  # never changes

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """Nothing to learn."""

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        return self._weights.astype(np.float64), np.zeros(self._weights.shape)

    def weights(self, known_sd: float) -> tuple[np.ndarray, np.ndarray]:
        return self._weights, np.ones(self._weights.shape, dtype=bool)

    def sample(self, known_sd, connection_uniforms, sign_uniforms) -> np.ndarray:
        """K copies of the weights (every draw is the truth)."""
        return np.repeat(self._weights[None], connection_uniforms.shape[0], axis=0)

    def excitation_probability(self, target: int, known_sd: float) -> np.ndarray:
        return (self._weights[:, target] > 0).astype(np.float64)


class ObservedState:
    """The simulator state of the observed network, tracked from observations and actions.

    Spikes are read from the observed potential (>= V_th, less ``spike_margin_mV``
    under noise); releases from the spikes and the vesicle rule; the potential after
    reset is V_r for a spiking neuron and the observation otherwise.
    """

    def __init__(self, n_neurons: int, params: NeuronParams, spike_margin_mV: float) -> None:
        self.params = params
        self.state = SimulatorState.at_rest(1, n_neurons, params)
        self._threshold = params.v_spike_mV - spike_margin_mV
        self._interval = params.min_release_interval_steps
        self.spiked = np.zeros(n_neurons, dtype=bool)
        # Each neuron's steps since its last release, counted before the last step's
        # release reset them (what a correction of that step's reads needs).
        self._since_before_release = np.zeros(n_neurons, dtype=np.int64)

    def observe(self, voltage: np.ndarray, action: int,
                drive_mV: np.ndarray | None = None) -> tuple[np.ndarray, ...]:  # fmt: skip
        """Take the observation after a step with ``action``; update the state.
        ``drive_mV`` [n]: the step's known input instead of the action's pulse (the
        opsin's current under the ChR2 actuator; the action then pulses nothing).

        Returns ``(released_before [n], residual [n] in units of w_in, observed [n])``:
        the evidence of this step for :meth:`ConnectivityEstimate.add`.
        """
        state, params = self.state, self.params
        voltage = np.asarray(voltage, dtype=np.float64)
        before = state.voltage_mV[0]
        refractory = state.refractory_left[0] > 0
        stimulus = np.zeros_like(before) if drive_mV is None else drive_mV
        if action != DO_NOTHING and drive_mV is None:
            stimulus[action] = params.stimulus_step_mV
        # The potential without synaptic input; the residual is what the synapses added.
        predicted = integrate(before, params.v_rest_mV, self._leak(), stimulus)
        residual = (voltage - predicted) / params.synaptic_step_mV
        released_before = state.released[0].astype(np.float64)
        observed = ~refractory
        self._apply(self._read(voltage, observed), refractory, voltage)
        return released_before, residual, observed

    def _leak(self) -> float | np.ndarray:
        """dt / RC of the neurons (the paper's, the same for all)."""
        return self.params.leak_per_step

    def _read(self, voltage: np.ndarray, observed: np.ndarray) -> np.ndarray:
        """[n] which observed neurons spiked at the potentials ``voltage``."""
        return observed & (voltage >= self._threshold)

    def _apply(self, spiked: np.ndarray, refractory: np.ndarray, voltage: np.ndarray) -> None:
        """Advance the tracked state by the step's reads (releases by the vesicle rule)."""
        state, params = self.state, self.params
        since = np.minimum(state.steps_since_release[0] + 1, SINCE_RELEASE_CAP)
        self._since_before_release = since.copy()
        release = spiked & (since >= self._interval)
        since[release] = 0
        state.voltage_mV[0] = np.where(spiked | refractory, params.v_rest_mV, voltage)
        state.refractory_left[0] = np.where(
            spiked, params.refractory_steps, np.maximum(state.refractory_left[0] - 1, 0)
        )
        state.steps_since_release[0] = since
        state.released[0] = release
        self.spiked = spiked

    def _correct(self, neuron: int, spiked: bool, potential: float) -> None:
        """Change the last step's read of ``neuron`` to ``spiked`` (it showed
        ``potential``): its potential, refractoriness and release as :meth:`_apply` would
        have set them (what a tracker that settles reads a step later calls)."""
        state, params = self.state, self.params
        since = int(self._since_before_release[neuron])
        release = spiked and since >= self._interval
        state.voltage_mV[0, neuron] = params.v_rest_mV if spiked else potential
        state.refractory_left[0, neuron] = params.refractory_steps if spiked else 0
        state.steps_since_release[0, neuron] = 0 if release else since
        state.released[0, neuron] = release
        self.spiked[neuron] = spiked
