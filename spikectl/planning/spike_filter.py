"""Identify the connectivity from spikes alone (spikes-only sensing, the ``"spikes"``
estimator).

Under spikes-only sensing (``Extensions(sensing="spikes")``) the agent sees which
neurons spiked, not their potentials. On the paper's deterministic model that loses
nothing a filter cannot rebuild: neuron j's potential is a function of its own input
column G[:, j], the releases of every neuron (which follow from the observed spikes by
the vesicle rule) and the stimulations that landed on j. So for each neuron and each of
its 3^(n-1) columns in {-1, 0, +1} the filter keeps the potential that column implies,
stepped with the kernel's own Euler arithmetic (:func:`~spikectl.neuron.kernel.
integrate`), and drops a column the moment it predicts a spike that did not happen or
misses one that did. The true column is never dropped; the likelihood of the spikes
factorises over the columns given all observed spikes.

The prior does not factorise: Dale's law gives each neuron one sign for all of its
outgoing synapses (excitatory with probability 0.8), shared by every column. The
posterior is kept exactly with the row signs as a latent vector s in {-1, +1}^n: given
s the columns are independent (each entry a connection of its distance's probability,
of its row's sign), so with Z_j(s) the prior mass of column j's surviving hypotheses that
agree with s,

    P(s | spikes) ~ prior(s) prod_j Z_j(s),   P(column h of j | spikes) =
    b_h sum_s [h agrees with s] P(s | spikes) / Z_j(s),

where b_h is h's connection prior. (The generator's conditioning on the target having
an excitatory input and on the pattern is not modelled, as in every other estimator.)
That costs 2^n x 3^(n-1) numbers per column, so the filter is exact up to
:data:`MAX_SPIKE_FILTER_NEURONS` neurons and refuses larger networks
(:class:`SpikeFilterTooLarge`). A spike the model cannot produce under any surviving
column (the environment is not the paper's deterministic model) is refused too
(:class:`SpikesInconsistent`): nothing here degrades silently.

:class:`SpikeState` is the tracker the observation part reads spikes with: refractory
neurons, releases and stimulations from the spikes and the actions, and the potentials
the planner starts from, each neuron's posterior mean over its surviving columns.
"""

from __future__ import annotations

import itertools
import math

import numba
import numpy as np

from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.neuron.kernel import integrate
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning import portable
from spikectl.planning.discrete import DiscreteConnectivityEstimate
from spikectl.planning.identify import ObservedState

MAX_SPIKE_FILTER_NEURONS = 8
"""Largest network the exact filter keeps: 2^n sign vectors x 3^(n-1) columns per neuron
(at n = 8, 256 x 2 187; at n = 9 the agreement tables alone would take 240 MB)."""


class SpikeFilterTooLarge(ValueError):
    """The network is larger than the exact spike filter keeps."""


class SpikesInconsistent(ValueError):
    """The observed spikes are impossible under every input column of some neuron: the
    environment is not the paper's deterministic model the filter assumes."""


def spike_filter_fits(n_neurons: int) -> bool:
    """Whether the exact spike filter keeps a network of ``n_neurons``."""
    return 2 <= n_neurons <= MAX_SPIKE_FILTER_NEURONS


class SpikeFilter(DiscreteConnectivityEstimate):
    """The exact posterior over G from spikes alone, with each surviving column's
    current potential.

    It answers the estimators' protocol (``posterior``, ``weights``, ``sample``,
    ``excitation_probability`` through its columns' posterior weights) but takes a
    step's evidence as :class:`SpikeState` reads it: ``add(released, drive_mV, spiked,
    observed)``.

    Attributes:
        alive: bool [n (post), M] the columns still consistent with every spike.
        potentials: float64 [n (post), M] the potential (after reset) each column implies.
    """

    # (hypotheses as floats [n, M, n], agreement [n, M, S] uint8, column prior b [n, M],
    # sign log-prior [S], signs [S, n]) of each size, built once (read only).
    _TABLES: dict[int, tuple[np.ndarray, ...]] = {}
    # (Z_j(s) [n, S], log_weights [n, M]) of the prior of each size.
    _PRIORS: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def __init__(self, n_neurons: int, params: NeuronParams) -> None:
        if not spike_filter_fits(n_neurons):
            raise SpikeFilterTooLarge(
                f"identify-and-plan from spikes only keeps 2^n sign vectors x 3^(n-1) input "
                f"columns per neuron, exactly; n = {n_neurons} is outside its range of 2 to "
                f"{MAX_SPIKE_FILTER_NEURONS} neurons"
            )
        super().__init__(n_neurons, 1.0)  # the residual noise is unused: spikes are exact
        self.params = params
        if n_neurons not in self._TABLES:
            self._TABLES[n_neurons] = _tables(self.hypotheses)
        # Shared by every filter of this size (a vector environment keeps one per network).
        self._values, self._agreement, self._column_prior, self._sign_log_prior, self._signs = (
            self._TABLES[n_neurons]
        )
        self.alive = np.ones(self.log_weights.shape, dtype=bool)
        self.potentials = np.full(self.log_weights.shape, float(params.v_rest_mV))
        # Each column's surviving hypotheses (what the posterior sums over: its cost
        # falls as columns are dropped).
        self._surviving = [np.arange(self.log_weights.shape[1])] * n_neurons
        if n_neurons not in self._PRIORS:
            self._column_mass = np.empty((n_neurons, self._signs.shape[0]))  # Z_j(s)
            for j in range(n_neurons):
                _column_mass(self._agreement[j], self._surviving[j], self._weighted_prior(j),
                             self._column_mass[j])  # fmt: skip
            self._update_posterior()
            self._PRIORS[n_neurons] = (self._column_mass, self.log_weights)
        self._column_mass = self._PRIORS[n_neurons][0].copy()
        self.log_weights = self._PRIORS[n_neurons][1].copy()

    def add(self, released: np.ndarray, drive_mV: np.ndarray, spiked: np.ndarray,
            observed: np.ndarray) -> None:  # fmt: skip
        """One step's evidence: ``released`` [n] which neurons released at the step
        before, ``drive_mV`` [n] the stimulation that landed on each, ``spiked`` [n] which
        spiked now, ``observed`` [n] which were not refractory (integrated this step)."""
        params = self.params
        spiked = np.asarray(spiked, dtype=bool)
        rows = self._integrated_rows(observed)
        if not rows.size:
            return
        potential = self._column_potentials(rows, released, drive_mV)
        fires = potential >= params.v_spike_mV  # [k, M]
        agrees = fires == spiked[rows, None]
        alive = self.alive[rows] & agrees
        dead = np.flatnonzero(~alive.any(axis=1))
        if dead.size:
            raise SpikesInconsistent(
                f"neuron {int(rows[dead[0]])}'s spikes are impossible under every input "
                "column: the environment is not the paper's deterministic model (the spike "
                "filter takes no noise, stochastic release, background input, hidden or "
                "heterogeneous neurons)"
            )
        self.potentials[rows] = np.where(spiked[rows, None], params.v_rest_mV, potential)
        changed = rows[(alive != self.alive[rows]).any(axis=1)]
        self.alive[rows] = alive
        self.observations += int(rows.size)
        if changed.size:
            self._columns_changed(changed)

    def _columns_changed(self, changed: np.ndarray) -> None:
        """The posterior again after neurons ``changed`` kept other columns."""
        for j in changed:
            self._surviving[j] = np.flatnonzero(self.alive[j])
            _column_mass(self._agreement[j], self._surviving[j], self._weighted_prior(j),
                         self._column_mass[j])  # fmt: skip
        self._update_posterior()
        self.version += 1
        self._cache = None

    def _integrated_rows(self, observed: np.ndarray) -> np.ndarray:
        """The neurons integrated this step (not refractory); the others rest."""
        held = np.flatnonzero(~np.asarray(observed, dtype=bool))
        self.potentials[held] = self.params.v_rest_mV
        return np.flatnonzero(observed)

    def _column_potentials(self, rows: np.ndarray, released: np.ndarray,
                           drive_mV: np.ndarray,
                           extra_mV: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """[k, M] each kept column's potential of neurons ``rows`` after the step: the
        kernel's arithmetic, the summed weights times w_in plus the stimulus (plus
        ``extra_mV`` [k, M], a drive that depends on the column's potential)."""
        params = self.params
        counts = portable.matmul(self._values[rows], np.asarray(released, dtype=np.float64))
        drive = params.synaptic_step_mV * counts + np.asarray(drive_mV)[rows, None]
        if extra_mV is not None:
            drive = drive + extra_mV
        return integrate(self.potentials[rows], params.v_rest_mV, params.leak_per_step,
                         drive)  # fmt: skip

    def _weighted_prior(self, j: int) -> np.ndarray:
        """[M] column j's prior weights as the posterior reads them (the likelihood
        filter weighs them by the spikes)."""
        return self._column_prior[j]

    def _update_posterior(self) -> None:
        """Each column's posterior weight (``log_weights``, what the marginals and the
        draws read) from the surviving columns and the row signs' posterior."""
        log_mass = portable.log(self._column_mass)  # [n, S]
        log_signs = self._sign_log_prior.copy()
        for j in range(self.n_neurons):  # summed in index order: the same bits everywhere
            log_signs += log_mass[j]
        signs = portable.exp(log_signs - log_signs.max())
        signs /= signs.sum()
        share = np.divide(signs[None, :], self._column_mass,
                          out=np.zeros_like(self._column_mass),
                          where=self._column_mass > 0)  # fmt: skip  # [n, S]: P(s) / Z_j(s)
        weights = np.empty(self.log_weights.shape)
        for j in range(self.n_neurons):
            _column_weights(self._agreement[j], self._surviving[j], self._weighted_prior(j),
                            share[j], weights[j])  # fmt: skip
        self.log_weights = portable.log(weights / weights.sum(axis=1, keepdims=True))

    def column_weights(self) -> np.ndarray:
        """[n (post), M] each column's posterior probability (0 for a dropped one)."""
        return portable.exp(self.log_weights)

    def mean_potentials(self) -> np.ndarray:
        """[n] each neuron's posterior mean potential (after reset), as V_r plus the mean
        distance from it (exactly V_r where every surviving column is at rest)."""
        rest = self.params.v_rest_mV
        distance = portable.matmul(self.column_weights()[:, None, :],
                                   (self.potentials - rest)[:, :, None])[:, 0, 0]  # fmt: skip
        return rest + distance

    def _apply_dale(self) -> None:
        """Nothing to do: Dale's law is in the posterior exactly (the row signs)."""


def _tables(hypotheses: np.ndarray) -> tuple[np.ndarray, ...]:
    """(the hypotheses as floats; agreement [n, M, S]: column h of neuron j agrees with s;
    connection prior b [n, M]; log-prior of each sign vector [S]; the sign vectors
    [S, n]) for ``hypotheses`` [n (post), M, n (pre)]."""
    n = hypotheses.shape[0]
    signs = np.array(list(itertools.product((-1, 1), repeat=n)), dtype=np.int8)  # [S, n]
    agreement = np.empty((n, hypotheses.shape[1], signs.shape[0]), dtype=np.uint8)
    for j in range(n):
        h = hypotheses[j][:, None, :]  # [M, 1, n]
        agreement[j] = ((h == 0) | (h == signs[None])).all(axis=2)
    index = np.arange(n)
    probability = connection_probability(np.abs(index[:, None] - index[None, :]))
    np.fill_diagonal(probability, 0.0)  # no self-connections: h[j, :, j] is always 0
    column_prior = np.ones(hypotheses.shape[:2])
    sign_log_prior = np.zeros(signs.shape[0])
    for i in range(n):  # products and sums in index order: the same bits everywhere
        p = probability[i][:, None]  # [post, 1]: P(i -> j)
        column_prior *= np.where(hypotheses[:, :, i] != 0, p, 1.0 - p)
        sign_log_prior += np.where(signs[:, i] > 0, math.log(EXCITATORY_PROBABILITY),
                                   math.log1p(-EXCITATORY_PROBABILITY))  # fmt: skip
    tables = (hypotheses.astype(np.float64), agreement, column_prior, sign_log_prior, signs)
    for table in tables:
        table.flags.writeable = False
    return tables


_JIT = {"cache": True, "fastmath": False, "nogil": True}


@numba.njit(**_JIT)
def _column_mass(agreement, surviving, prior, out):
    """out[s] = Z_j(s): the prior mass of the ``surviving`` columns (ascending) that
    agree with sign vector s (``agreement`` uint8 [M, S], ``prior`` [M])."""
    out[:] = 0.0
    for m in surviving:
        for s in range(out.shape[0]):
            if agreement[m, s]:
                out[s] += prior[m]


@numba.njit(**_JIT)
def _column_weights(agreement, surviving, prior, share, out):
    """out[m] = b_m sum_s [m agrees with s] P(s) / Z_j(s) for the ``surviving`` columns,
    0 for the others."""
    out[:] = 0.0
    for m in surviving:
        total = 0.0
        for s in range(share.shape[0]):
            if agreement[m, s]:
                total += share[s]
        out[m] = prior[m] * total


class SpikeState(ObservedState):
    """The simulator state of the observed network tracked from spikes and actions: who
    is refractory, who released (the vesicle rule on the observed spikes), and the
    potentials the spike filter implies (:meth:`follow`)."""

    def observe(self, spikes: np.ndarray, action: int,
                drive_mV: np.ndarray | None = None) -> tuple[np.ndarray, ...]:  # fmt: skip
        """Take the spikes after a step with ``action``; update the state. Returns
        ``(released_before, drive_mV, spiked, observed)``, :meth:`SpikeFilter.add`'s
        evidence."""
        if drive_mV is not None:
            raise ValueError("the spike filter plays the current pulse alone, not an opsin")
        state, params = self.state, self.params
        spikes = np.asarray(spikes)
        if spikes.shape != self.spiked.shape or not np.isin(spikes, (0, 1)).all():
            raise ValueError(f"spikes must be {self.spiked.shape[0]} values in {{0, 1}}, "
                             f"got {spikes!r}")  # fmt: skip
        spiked = spikes.astype(bool)
        refractory = state.refractory_left[0] > 0
        if (spiked & refractory).any():
            raise SpikesInconsistent(
                f"neurons {np.flatnonzero(spiked & refractory).tolist()} spiked while "
                "refractory: the environment is not the paper's model"
            )
        drive = np.zeros(spiked.shape[0])
        if action != DO_NOTHING:
            drive[action] = params.stimulus_step_mV
        released_before = state.released[0].astype(np.float64)
        self._apply(spiked, refractory, state.voltage_mV[0])
        return released_before, drive, spiked, ~refractory

    def follow(self, estimate: SpikeFilter) -> None:
        """Take the potentials of ``estimate`` (after it took this step's evidence):
        each neuron's posterior mean, V_r where it spiked or is held."""
        held = self.spiked | (self.state.refractory_left[0] > 0)
        self.state.voltage_mV[0] = np.where(held, self.params.v_rest_mV,
                                            estimate.mean_potentials())  # fmt: skip
