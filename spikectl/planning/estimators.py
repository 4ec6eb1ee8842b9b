"""Identify-and-plan's estimator part: which posterior over the connectivity G it keeps,
and the weights it plans with.

The estimates themselves live in their own modules (:mod:`~spikectl.planning.identify`,
:mod:`~spikectl.planning.bayes`, :mod:`~spikectl.planning.particles`,
:mod:`~spikectl.planning.relays`, :mod:`~spikectl.planning.spike_filter`); this part
chooses one by name from :data:`ESTIMATORS` (a :class:`~spikectl.registry.Registry`: a
plug-in registers another the public way) and turns it into the planner's network. Every
estimate answers the :class:`ConnectivityBelief` protocol (the spike filter takes its own
evidence, what spikes-only sensing gives).

The planner plans known entries (posterior standard deviation below ``known_sd``) at
their rounded value and, without measurement noise, the others at their posterior mean
(rounded to 0.01 w_in), which carries the summed effect of neurons that only ever
released together; under noise that mean is noisy and unknown entries are planned as 0
(chosen on training networks at 1, 2 and 4 mV, docs/baselines.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from spikectl.neuron.params import NeuronParams
from spikectl.planning.bayes import BayesConnectivityEstimate, ObservationModel
from spikectl.planning.discrete import column_hypotheses_fit
from spikectl.planning.identify import ConnectivityEstimate
from spikectl.planning.particles import ParticleConnectivityEstimate
from spikectl.planning.relays import RelayConnectivityEstimate, relay_weights
from spikectl.planning.spike_filter import SpikeFilter
from spikectl.planning.spike_likelihood import SpikeLikelihoodFilter
from spikectl.registry import Registry

PLANNED_MEAN_RESOLUTION = 2
"""Decimals (of w_in) the posterior mean of an unknown entry is planned at: tiny changes
of the mean then do not force a re-plan."""


class ConnectivityBelief(Protocol):
    """What identify-and-plan asks of an estimate of G (signed weights in units of w_in,
    [n (pre), n (post)])."""

    version: int
    """Counts the changes of the posterior (what may be cached against it)."""

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """One step's evidence (:meth:`~spikectl.planning.identify.ObservedState.observe`)."""

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of G."""

    def weights(self, known_sd: float) -> tuple[np.ndarray, np.ndarray]:
        """(int8 signs to plan with, known bool), both [n, n]."""

    def sample(self, known_sd: float, connection_uniforms: np.ndarray,
               sign_uniforms: np.ndarray) -> np.ndarray:  # fmt: skip
        """int8 [K, n, n] networks drawn from the posterior by the uniforms given."""

    def excitation_probability(self, target: int, known_sd: float) -> np.ndarray:
        """[n] P(neuron i excites ``target``)."""


EstimateFactory = Callable[[int, float, ObservationModel, NeuronParams], ConnectivityBelief]
"""(n_neurons, residual_sd in w_in, the task's observation model, params) -> a fresh
estimate for one episode."""


def gaussian(n: int, residual_sd: float, model: ObservationModel, params: NeuronParams):
    """:class:`~spikectl.planning.identify.ConnectivityEstimate`: ridge regression per
    column, any n."""
    return ConnectivityEstimate(n, residual_sd)


def bayes(n: int, residual_sd: float, model: ObservationModel, params: NeuronParams):
    """:class:`~spikectl.planning.bayes.BayesConnectivityEstimate`, the exact posterior
    over {-1, 0, +1} under the task's observation model, where its columns fit (n <= 11);
    the Gaussian estimate above."""
    if column_hypotheses_fit(n):
        return BayesConnectivityEstimate(n, model, params)
    return ConnectivityEstimate(n, residual_sd)


def particles(n: int, residual_sd: float, model: ObservationModel, params: NeuronParams):
    """:class:`~spikectl.planning.particles.ParticleConnectivityEstimate`: the posterior
    over {-1, 0, +1} on the entries the evidence touched, any n."""
    return ParticleConnectivityEstimate(n, residual_sd)


def relays(n: int, residual_sd: float, model: ObservationModel, params: NeuronParams):
    """:class:`~spikectl.planning.relays.RelayConnectivityEstimate`: the Gaussian estimate
    with each observed neuron's effect two steps after its release (through hidden
    neurons), planned through virtual relay neurons."""
    return RelayConnectivityEstimate(n, residual_sd)


def spikes(n: int, residual_sd: float, model: ObservationModel, params: NeuronParams):
    """:class:`~spikectl.planning.spike_filter.SpikeFilter`: the exact posterior from
    spikes alone (spikes-only sensing) with each surviving column's potential, n <= 8."""
    return SpikeFilter(n, params)


def spike_likelihood(n: int, residual_sd: float, model: ObservationModel,
                     params: NeuronParams):  # fmt: skip
    """:class:`~spikectl.planning.spike_likelihood.SpikeLikelihoodFilter`: the posterior
    from spikes under the task's background input (``model``) and the ChR2 light, each
    column weighed by the likelihood of the spikes, n <= 8."""
    rate = -math.log1p(-model.background_probability)
    return SpikeLikelihoodFilter(n, params, rate, model.background_step * params.synaptic_step_mV)


ESTIMATORS: Registry[EstimateFactory] = Registry("estimator")
"""The estimates identify-and-plan can keep, by name (:class:`EstimatorSettings.kind`)."""
ESTIMATORS.register("gaussian", gaussian)
ESTIMATORS.register("bayes", bayes)
ESTIMATORS.register("particles", particles)
ESTIMATORS.register("relays", relays)
ESTIMATORS.register("spikes", spikes)
ESTIMATORS.register("spike-likelihood", spike_likelihood)

SPIKE_ESTIMATORS = {"spikes", "spike-likelihood"}
"""The estimators that identify from spikes alone (their evidence is what
:class:`~spikectl.planning.spike_filter.SpikeState` reads) and set the tracked potentials;
they play spikes-only sensing, the others potentials."""

RIG_SPIKE_ESTIMATORS = {"spike-likelihood"}
"""The spike estimators that read the task's model (``task_model=True``: background input
and the ChR2 light, :class:`~spikectl.planning.spike_likelihood.SpikeLikelihoodState`'s
evidence); a plug-in that does adds its name."""

RELAY_ESTIMATORS = {"relays"}
"""The estimators whose estimate answers ``relay_signs`` and is planned with virtual relay
neurons (:mod:`spikectl.planning.relays`); a plug-in that keeps relays adds its name."""


@dataclass(frozen=True)
class EstimatorSettings:
    """The estimator part: which estimate (``kind``, a name in :data:`ESTIMATORS`) and
    when an entry counts as known.

    Attributes:
        kind: ``"gaussian"`` (ridge regression, any n), ``"bayes"`` (the exact posterior
            under the task's observation model, n <= 11, else Gaussian),
            ``"particles"`` (the discrete posterior at any n), ``"relays"`` (the Gaussian
            one with relays through hidden neurons), ``"spikes"`` (the exact posterior
            from spikes alone, spikes-only sensing, n <= 8), ``"spike-likelihood"``
            (from spikes under background input and the ChR2 light, n <= 8), or a
            registered plug-in.
        known_sd: an entry counts as known below this posterior standard deviation
            (units of w_in).
    """

    kind: str = "gaussian"
    known_sd: float = 0.25

    def __post_init__(self) -> None:
        ESTIMATORS.entry(self.kind)  # an unknown name: one line naming the registered ones
        if isinstance(self.known_sd, bool) or not self.known_sd > 0:
            raise ValueError(f"known_sd must be > 0, got {self.known_sd!r}")

    @property
    def plans_relays(self) -> bool:
        """Whether the plan holds a virtual relay neuron per observed neuron."""
        return self.kind in RELAY_ESTIMATORS

    def new(self, n: int, residual_sd: float, model: ObservationModel, params: NeuronParams):
        """A fresh estimate for an episode on ``n`` observed neurons."""
        return ESTIMATORS.load(self.kind)(n, residual_sd, model, params)

    def planning_weights(
        self, estimate: ConnectivityBelief, plan_mean: bool, strengths: bool, relayed: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """(weights to plan with, known [n, n]): known entries at their rounded value
        (at their estimated strength where ``strengths``: synapses differ in strength);
        unknown ones at their posterior mean where ``plan_mean``, else 0. ``relayed``:
        [2n, 2n] with the virtual relay neurons of ``estimate.relay_signs``; ``known``
        stays [n, n] (what is known among the observed)."""
        signs, known = estimate.weights(self.known_sd)
        if plan_mean or strengths:
            mean = np.round(estimate.posterior()[0], PLANNED_MEAN_RESOLUTION)
            if strengths:
                signs = np.where(known, mean, signs)
            if plan_mean:
                signs = np.where(known, signs, mean)
        if relayed:
            signs = relay_weights(signs, estimate.relay_signs(self.known_sd))
        return signs, known
