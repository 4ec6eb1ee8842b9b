"""The exact posterior over each column of G under the task's own observation model.

:class:`~spikectl.planning.discrete.DiscreteConnectivityEstimate` keeps a weight on
each of the 3^(n-1) columns G[:, j] in {-1, 0, +1} under the generator's prior, and
takes every residual (what the synapses added to neuron j, in units of w_in) as the
column's sum over the neurons that released, plus Gaussian noise and a small outlier
part. :class:`BayesConnectivityEstimate` replaces that likelihood with the one the task
defines (:class:`ObservationModel`, read from the environment's
:class:`~spikectl.neuron.extensions.Extensions`):

* **measurement noise**: Gaussian, of the task's level (the residual differences two
  noisy potentials, the older one shrunk by the leak);
* **stochastic release**: a neuron that spiked released with the probability the
  release rule gives it, p_r (1 - exp(-k dt / tau_R)) after k steps; the likelihood is
  the exact mixture over which of the spiking neurons released (Bernoulli each);
* **background input**: with the probability of at least one spontaneous input in
  the step (Poisson, the task's rate), the residual carries one more input of the
  task's size;
* **heterogeneous synapses**: each released synapse's strength is spread uniformly by
  the task's factor, which adds its variance to the residual's per nonzero synapse.

Hidden neurons' releases and heterogeneous thresholds stay in the outlier part. The
residuals themselves are computed as before (:class:`~spikectl.planning.identify.
ObservedState`, the kernel's own Euler step): only what they are taken to mean changes.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning import portable
from spikectl.planning.discrete import (
    _OUTLIER_RANGE,
    MIN_RESIDUAL_SD,
    OUTLIER_PROBABILITY,
    DiscreteConnectivityEstimate,
)

MAX_UNCERTAIN_RELEASES = 6
"""Spiking neurons whose release is enumerated exactly (2^6 subsets); any beyond these
enter with their release probability as a sure fractional input."""


@dataclass(frozen=True)
class ObservationModel:
    """What a residual means on a task: the environment-level facts the posterior uses.

    Attributes:
        noise_mV: sigma of the Gaussian measurement noise on observed potentials.
        stochastic_release: whether a spike releases with the release rule's
            probability (True) or by the paper's deterministic rule.
        background_probability: chance of a spontaneous input to a neuron in one step.
        background_step: that input's size in units of w_in (signed).
        synaptic_spread: each synapse's strength is w_in times a factor uniform in
            [1 - s, 1 + s].
    """

    noise_mV: float = 0.0
    stochastic_release: bool = False
    background_probability: float = 0.0
    background_step: float = 1.0
    synaptic_spread: float = 0.0

    @classmethod
    def of(cls, extensions: Extensions | None, params: NeuronParams) -> ObservationModel:
        """The model of an environment with ``extensions`` (None: the paper's)."""
        if extensions is None:
            return cls()
        return cls(
            noise_mV=float(extensions.observation_noise_mV),
            stochastic_release=bool(extensions.stochastic_release),
            background_probability=-math.expm1(-float(extensions.background_rate)),
            background_step=extensions.background_current_pA / params.synaptic_current_pA,
            synaptic_spread=float(extensions.synaptic_spread),
        )

    def residual_sd(self, params: NeuronParams) -> float:
        """The residual's noise in units of w_in (at least :data:`MIN_RESIDUAL_SD`)."""
        noise = self.noise_mV * math.hypot(1.0, 1.0 - params.leak_per_step)
        return max(noise / params.synaptic_step_mV, MIN_RESIDUAL_SD)


def release_chances(spiked: np.ndarray, steps_since_release: np.ndarray,
                    params: NeuronParams) -> np.ndarray:  # fmt: skip
    """[n] the chance that each neuron released at a step where ``spiked``, k =
    ``steps_since_release`` steps after its last release (stochastic release):
    p_r (1 - exp(-k dt / tau_R)), 0 where it did not spike."""
    k = np.asarray(steps_since_release, dtype=np.float64)
    chance = params.release_scale * -portable.expm1(-k * params.recovery_per_step)
    return np.where(spiked, np.clip(chance, 0.0, 1.0), 0.0)


class BayesConnectivityEstimate(DiscreteConnectivityEstimate):
    """The exact per-column posterior (as :class:`DiscreteConnectivityEstimate`) with the
    likelihood of :class:`ObservationModel`; ``add`` takes release *probabilities*
    (1 for a sure release, 0 for none, in between for a spike that may have released)."""

    def __init__(self, n_neurons: int, model: ObservationModel, params: NeuronParams) -> None:
        super().__init__(n_neurons, model.residual_sd(params))
        self.model = model
        # The hypotheses as floats, and their indicators, made once (every step uses them).
        self._values = self.hypotheses.astype(np.float64)  # [post, M, pre]
        self._magnitudes = np.abs(self._values)
        self._plus = (self.hypotheses == 1).astype(np.float64)
        self._minus = (self.hypotheses == -1).astype(np.float64)
        self._marginal_cache: tuple[np.ndarray, np.ndarray] | None = None

    def _marginals(self) -> tuple[np.ndarray, np.ndarray]:
        """(P(G = +1), P(G = -1)), both [n (pre), n (post)] (as the discrete estimate's,
        by batched matrix products; kept until the weights change)."""
        if self._marginal_cache is not None:
            return self._marginal_cache
        weights = portable.exp(self.log_weights - self.log_weights.max(axis=1, keepdims=True))
        weights /= weights.sum(axis=1, keepdims=True)  # [post, M]
        plus = portable.matmul(weights[:, None, :], self._plus)[:, 0, :].T
        minus = portable.matmul(weights[:, None, :], self._minus)[:, 0, :].T
        self._marginal_cache = (plus, minus)
        return plus, minus

    def _apply_dale(self) -> None:
        signs = self._row_sign.copy()
        super()._apply_dale()
        if not np.array_equal(signs, self._row_sign):  # the weights changed
            self._marginal_cache = None

    def log_likelihood(self, released: np.ndarray, residual: np.ndarray,
                       observed: np.ndarray) -> np.ndarray:  # fmt: skip
        """[k, M] log P(residual_j | column hypothesis m) for the k observed columns."""
        released = np.asarray(released, dtype=np.float64)
        observed = np.flatnonzero(observed)
        uncertain = np.flatnonzero((released > 0) & (released < 1))[:MAX_UNCERTAIN_RELEASES]
        sure = released.copy()
        sure[uncertain] = 0.0
        hypotheses = self._values[observed]  # [k, M, n]
        base = portable.matmul(hypotheses, sure)  # [k, M]
        parts = hypotheses[:, :, uncertain]  # [k, M, u]
        spread = self.model.synaptic_spread
        if spread > 0:
            magnitudes = self._magnitudes[observed]
            base_synapses = portable.matmul(magnitudes, sure)
            part_synapses = magnitudes[:, :, uncertain]
        r = np.asarray(residual, dtype=np.float64)[observed, None]  # [k, 1]
        rho = self.model.background_probability
        q = released[uncertain]
        density = np.zeros(base.shape)
        for subset in itertools.product((0.0, 1.0), repeat=uncertain.shape[0]):
            chosen = np.array(subset)
            probability = float(np.prod(np.where(chosen > 0, q, 1.0 - q)))
            mean = base + portable.matmul(parts, chosen) if uncertain.size else base
            sd = self.residual_sd
            if spread > 0:
                # Each released nonzero synapse adds the variance of its strength, a
                # factor uniform in [1 - s, 1 + s] (variance s^2 / 3).
                synapses = (base_synapses + portable.matmul(part_synapses, chosen)
                            if uncertain.size else base_synapses)  # fmt: skip
                sd = np.sqrt(self.residual_sd**2 + synapses * spread**2 / 3.0)
            part = _normal(r, mean, sd)
            if rho > 0:
                part = (1.0 - rho) * part + rho * _normal(r, mean + self.model.background_step, sd)
            density += probability * part
        outlier = OUTLIER_PROBABILITY / _OUTLIER_RANGE
        return portable.log((1.0 - OUTLIER_PROBABILITY) * density + outlier)

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """One step's evidence: ``released`` [n] release probabilities of the previous
        step, ``residual`` [n] in units of w_in, ``observed`` [n] bool columns."""
        if not observed.any() or not np.any(released):
            return
        observed = np.asarray(observed, dtype=bool)
        self.log_weights[observed] += self.log_likelihood(released, residual, observed)
        self.log_weights[observed] -= self.log_weights[observed].max(axis=1, keepdims=True)
        self.observations += int(observed.sum())
        self.version += 1
        self._cache = self._marginal_cache = None
        self._apply_dale()


def _normal(x: np.ndarray, mean: np.ndarray, sd: np.ndarray | float) -> np.ndarray:
    return portable.exp(-0.5 * ((x - mean) / sd) ** 2) / (sd * math.sqrt(2.0 * math.pi))
