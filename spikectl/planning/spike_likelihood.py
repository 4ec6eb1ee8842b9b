"""Identify the connectivity from spikes under the rig's loop: the ChR2 light and background
input (the ``"spike-likelihood"`` estimator, the ``rig`` composition).

The exact spike filter (:mod:`~spikectl.planning.spike_filter`) drops a column the moment
the potential it implies mispredicts one spike: right on the paper's deterministic model,
fatal under background input, where a spontaneous +600 pA input makes a neuron spike
that no column predicts. This filter keeps the same columns, the same potentials and the
same exact Dale's-law posterior over the row signs, but weighs each column by the
likelihood of the spikes instead of dropping it:

- **the opsin's drive** is deterministic given the light that landed: the occupancies
  are tracked from the light alone (:class:`~spikectl.neuron.opsin.OpsinActuator`), and
  each column's drive is the current they pass at *that column's* potential, computed by
  the environment's own compiled :func:`~spikectl.neuron.opsin.current_pA`, so the
  potential a column implies is the one the environment's kernel computes for it;
- **a spike the column does not predict** costs the chance that spontaneous inputs
  caused it: P(N >= k) for the k inputs of the task's size the column's potential is
  short of the threshold (N Poisson at the background rate), at least
  ``unexplained_floor`` (by default the chance of one input, whatever k: one spontaneous
  input of 20 mV takes a neuron at or above rest over the threshold, and an earlier
  unseen input may have left the neuron closer than its column implies); a silent step
  where the column predicts none costs the complement;
- **a missed spike** (the column predicts one and none came) cannot come from a
  depolarising input: it costs :data:`MISS_PROBABILITY`, not zero, as a guard (after an
  unseen input the true column's potential is below the neuron's, and the opsin passes
  more current at a lower potential);
- the potentials resynchronise at every observed spike (the neuron resets to V_r, as in
  the exact filter), so an unseen input is forgotten at the neuron's next spike.

A column whose log-likelihood falls :data:`PRUNE_NATS` below its neuron's best column is
dropped (the posterior then sums over fewer columns: its cost falls as the exact
filter's does). Without background input the costs are zero and one, and the filter is
the exact one: the same surviving columns and posterior.

:class:`SpikeLikelihoodState` is its tracker: :class:`~spikectl.planning.spike_filter.
SpikeState` with the opsins' open fractions of the step read into the evidence.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spikectl.neuron.opsin import OpsinActuator, current_pA
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning import portable
from spikectl.planning.spike_filter import (
    SpikeFilter,
    SpikesInconsistent,
    SpikeState,
    _column_mass,
)

MISS_PROBABILITY = 1e-3
"""The likelihood of a silent step for a column that predicts a spike, under background
input (1e-2 scored the same on the ``rig`` validation networks, docs/results/iap-rig)."""
PRUNE_NATS = 16.0
"""A column is dropped once its log-likelihood is this far below its neuron's best
(three unexplained spikes at the ``rig`` task's background rate)."""


class SpikeLikelihoodFilter(SpikeFilter):
    """The posterior over G from spikes under the opsin and background input, with each
    kept column's current potential.

    ``background_rate``: spontaneous inputs per neuron and step (Poisson), each of
    ``background_step_mV`` (default: a synapse's, 20 mV). ``add(released, drive_mV,
    spiked, observed, open_fractions)``: as :meth:`SpikeFilter.add`, with
    ``open_fractions`` [2, n] the opsins' O1 and O2 at the step's start (None: the current
    pulse, no opsin).

    Attributes:
        log_likelihood: float64 [n (post), M] each column's log-likelihood of the spikes
            so far, relative to its neuron's best (-inf: dropped).
    """

    def __init__(self, n_neurons: int, params: NeuronParams, background_rate: float,
                 background_step_mV: float | None = None,
                 miss_probability: float = MISS_PROBABILITY, prune_nats: float = PRUNE_NATS,
                 unexplained_floor: float | None = None) -> None:  # fmt: skip
        if not 0.0 <= background_rate < 1.0:
            raise ValueError(f"background_rate must lie in [0, 1), got {background_rate!r}")
        if not 0.0 <= miss_probability < 1.0:
            raise ValueError(f"miss_probability must lie in [0, 1), got {miss_probability!r}")
        if not prune_nats > 0:
            raise ValueError(f"prune_nats must be > 0, got {prune_nats!r}")
        super().__init__(n_neurons, params)
        step = params.synaptic_step_mV if background_step_mV is None else background_step_mV
        if background_rate > 0 and not step > 0:
            raise ValueError(f"the background input must depolarise, got {step!r} mV")
        chance = -math.expm1(-background_rate)  # at least one spontaneous input
        floor = chance if unexplained_floor is None else unexplained_floor
        # log P(a spike | k inputs needed to reach the threshold), k = 1 .. len - 1, and of
        # silence; without background input the model is the paper's: no mismatch at all.
        self._log_spike, self._log_silent = _poisson_tails(background_rate, floor)
        self._background_step = step
        self._log_missed = _log(miss_probability if background_rate > 0 else 0.0)
        self.prune_nats = float(prune_nats)
        self.mV_per_pA = params.dt_ms / params.capacitance_pF
        self.log_likelihood = np.zeros(self.log_weights.shape)

    def add(self, released: np.ndarray, drive_mV: np.ndarray, spiked: np.ndarray,
            observed: np.ndarray, open_fractions: np.ndarray | None = None) -> None:  # fmt: skip
        """One step's evidence (:meth:`SpikeFilter.add`'s, and the opsins' open fractions
        [2, n] at the step's start, or None)."""
        params = self.params
        spiked = np.asarray(spiked, dtype=bool)
        rows = self._integrated_rows(observed)
        if not rows.size:
            return
        light = None
        if open_fractions is not None:  # the light's current at each column's potential
            light = np.empty(self.potentials[rows].shape)
            _opsin_drive(open_fractions[0][rows], open_fractions[1][rows],
                         self.potentials[rows], self.mV_per_pA, light)  # fmt: skip
        potential = self._column_potentials(rows, released, drive_mV, light)
        fires = potential >= params.v_spike_mV  # [k, M]
        # The spontaneous inputs a silent column needs to reach the threshold (>= 1).
        needed = np.ceil((params.v_spike_mV - potential) / self._background_step)
        needed = np.clip(np.nan_to_num(needed, nan=1.0), 1, self._log_spike.size - 1)
        needed = needed.astype(np.int64)
        step = np.where(
            spiked[rows, None],
            np.where(fires, 0.0, self._log_spike[needed]),
            np.where(fires, self._log_missed, self._log_silent[needed]),
        )
        self.potentials[rows] = np.where(spiked[rows, None], params.v_rest_mV, potential)
        self.observations += int(rows.size)
        # A neuron's posterior changes only where its kept columns' costs differ.
        alive = self.alive[rows]
        lowest = np.where(alive, step, np.inf).min(axis=1)
        highest = np.where(alive, step, -np.inf).max(axis=1)
        if (highest == -np.inf).any():  # possible only without background input
            dead = int(rows[np.flatnonzero(highest == -np.inf)[0]])
            raise SpikesInconsistent(
                f"neuron {dead}'s spikes are impossible under every input column without "
                "background input"
            )
        moved = lowest != highest
        changed = rows[moved]
        if changed.size:
            new = self.log_likelihood[changed] + step[moved]
            new -= new.max(axis=1, keepdims=True)
            new[new < -self.prune_nats] = -np.inf
            self.log_likelihood[changed] = new
            self.alive[changed] = new > -np.inf
        if changed.size:
            self._columns_changed(changed)

    def keep_only(self, weights: np.ndarray, columns: np.ndarray | None = None) -> None:
        """Keep each neuron's true input column alone, column j of ``weights`` [n, n] in
        {-1, 0, +1}: the posterior is then that network, and the potentials are still read
        from spikes (a diagnostic: the loop told the weights, docs/results/iap-rig).
        ``columns``: the neurons whose column is told (every neuron when None; the
        target's alone in docs/results/iap-spikes)."""
        weights = np.asarray(weights)
        if weights.shape != (self.n_neurons, self.n_neurons):
            raise ValueError(f"weights must be [{self.n_neurons}, {self.n_neurons}], got "
                             f"shape {weights.shape}")  # fmt: skip
        told = range(self.n_neurons) if columns is None else np.asarray(columns).reshape(-1)
        if columns is not None and (told.dtype.kind not in "iu" or not told.size
                                    or told.min() < 0 or told.max() >= self.n_neurons):
            raise ValueError(f"columns must be neuron indices 0 to {self.n_neurons - 1}, got "
                             f"{columns!r}")  # fmt: skip
        for j in told:
            truth = (self.hypotheses[j] == weights[:, j]).all(axis=1)
            if not truth.any():
                raise ValueError(f"column {j} of weights is no hypothesis (a self-connection "
                                 "or a value outside {-1, 0, +1})")  # fmt: skip
            self.log_likelihood[j] = np.where(truth, 0.0, -np.inf)
            self.alive[j] = truth
            self._surviving[j] = np.flatnonzero(truth)
            _column_mass(self._agreement[j], self._surviving[j], self._weighted_prior(j),
                         self._column_mass[j])  # fmt: skip
        self._update_posterior()
        self.version += 1
        self._cache = None

    def _weighted_prior(self, j: int) -> np.ndarray:
        """Column j's prior times its likelihood (relative to its best column); the prior
        alone while :class:`SpikeFilter`'s constructor builds the posterior."""
        if not hasattr(self, "log_likelihood"):
            return self._column_prior[j]
        return self._column_prior[j] * portable.exp(self.log_likelihood[j])


def _log(probability: float) -> float:
    return math.log(probability) if probability > 0 else -math.inf


_MOST_INPUTS = 8
"""Spontaneous inputs counted in one step (more: the same tail)."""


def _poisson_tails(rate: float, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """(log P(spike), log P(silence)) [_MOST_INPUTS + 1] for a column k = 1 .. spontaneous
    inputs short of the threshold: P(N >= k), N ~ Poisson(``rate``), at least ``floor``
    (an earlier unseen input may have left the neuron closer than its column implies);
    index 0 unused."""
    spike = np.empty(_MOST_INPUTS + 1)
    below, term = 0.0, math.exp(-rate)  # P(N < k), P(N = k - 1)
    for k in range(1, _MOST_INPUTS + 1):
        below += term
        term *= rate / k
        spike[k] = max(1.0 - below, floor) if rate > 0 else 0.0
    spike[0] = spike[1]
    return np.array([_log(p) for p in spike]), np.log1p(-spike)


@numba.njit(cache=True, nogil=True)
def _opsin_drive(o1, o2, potentials, mV_per_pA, out):
    """out[k, m] = the opsin's drive (mV) of neuron k at column m's potential: the
    environment's :func:`~spikectl.neuron.opsin.current_pA`, times dt / C, as its
    illumination kernel computes it."""
    for k in range(potentials.shape[0]):
        for m in range(potentials.shape[1]):
            out[k, m] = mV_per_pA * current_pA(o1[k], o2[k], potentials[k, m])


class SpikeLikelihoodState(SpikeState):
    """:class:`~spikectl.planning.spike_filter.SpikeState` under the ChR2 actuator: each
    step's evidence carries the opsins' open fractions at its start, and the opsins
    (tracked from the light that landed alone) are advanced through the step."""

    def observe(self, spikes: np.ndarray, action: int,
                opsin: OpsinActuator | None = None) -> tuple[np.ndarray, ...]:  # fmt: skip
        """Take the spikes after a step in which ``action`` landed (a light pulse where
        ``opsin`` is given, which is advanced through the step); returns
        :meth:`SpikeLikelihoodFilter.add`'s evidence."""
        if opsin is None:
            return (*super().observe(spikes, action), None)
        open_fractions = np.stack([opsin.o1[0], opsin.o2[0]])
        scratch = np.empty((1, 1, self.spiked.shape[0]))
        opsin.illuminate(self.state.voltage_mV, np.array([[action]], dtype=np.int64), scratch)
        # The light is the only stimulus: the kernel steps with no pulse.
        released, drive, spiked, observed = super().observe(spikes, DO_NOTHING)
        return released, drive, spiked, observed, open_fractions
