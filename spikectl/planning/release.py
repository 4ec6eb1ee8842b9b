"""Which spikes released, read from the next step's potentials (stochastic release).

Under stochastic release a spike releases only with its chance (at most ``p_r``,
:func:`~spikectl.planning.bayes.release_chances`), and whether it did shows one step
later, in the potentials of the neuron's postsynaptic neurons. Without measurement
noise and with the paper's neurons every residual is then an exact integer (in units of
w_in, :mod:`spikectl.planning.identify`):

    residual_j = sum over the neurons i that spiked of  released_i * G[i, j]

so the releases are a hidden 0/1 vector behind one step's residuals. Giving a regression
the chance itself (released_i = 0.65) where the release failed tells it that
0.65 * G[i, j] = 0, which, noise-free, nails every synapse of the row to 0: that was the
Gaussian estimate's largest error under stochastic release (docs/baselines.md).

:func:`release_posterior` weighs every combination of the m spikes' releases (2^m, m
rarely above 3) by its chances and by how well it explains each observed residual,
given the estimate's probability that each synapse is excitatory, absent or inhibitory.
:func:`settled_releases` keeps what that settles: a release that is sure either way
(within :data:`SETTLED`) enters as 0 or 1; one that is not (a row that may simply
have no synapse) withholds the columns its unknown synapses reach, so that nothing is
learned from a guess.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np

from spikectl.neuron.extensions import Extensions
from spikectl.planning import portable

MAX_UNCERTAIN = 8
"""Above this many spikes of unknown release in one step (2^m combinations) the
posterior is not computed: the chances are returned, and :func:`settled_releases`
settles none of them."""
SETTLED = 0.05
"""A release counts as settled when its posterior is within this of 0 or 1: chosen on
the ``stochastic`` train and validation sets (docs/results/release-settling)."""
INTEGER_TOLERANCE = 0.25
"""A residual further than this (in units of w_in) from an integer is not explained by
any release and is left out of the posterior (noise-free, it never is)."""
FLOOR = 1e-3
"""The least likelihood one residual gives a combination: an estimate's confident but
wrong synapse weakens a combination instead of ruling it out."""


def exact_residuals(extensions: Extensions | None) -> bool:
    """Whether the residuals are exact integers in an environment with ``extensions``:
    the paper's neurons and synapses, observed exactly (no measurement noise or
    bleaching, no hidden or heterogeneous neurons, no background input); stochastic
    release only decides which of them arrive."""
    if extensions is None:
        return True
    return not (extensions.observation_noise_mV > 0
                or extensions.bleaching_time_constant_steps is not None
                or extensions.hidden_neurons > 0 or extensions.hidden_fraction > 0
                or extensions.heterogeneous or extensions.background_rate > 0)  # fmt: skip


def release_posterior(
    chances: np.ndarray,
    residual: np.ndarray,
    observed: np.ndarray,
    excites: np.ndarray,
    inhibits: np.ndarray,
) -> np.ndarray:
    """[n] the probability that each neuron released at the last step.

    Args:
        chances: [n] each neuron's release chance at the last step (0 where it did not
            spike).
        residual: [n] this step's residuals in units of w_in.
        observed: [n] bool, the columns whose residual holds (not refractory).
        excites, inhibits: [n (pre), n (post)] the probability that each synapse is
            excitatory, inhibitory (:meth:`~spikectl.planning.identify.
            ConnectivityEstimate.entry_probabilities`).
    """
    chances = np.asarray(chances, dtype=np.float64)
    uncertain = np.flatnonzero(chances > 0)
    m = uncertain.size
    if m == 0 or m > MAX_UNCERTAIN:
        return chances.copy()
    combos = _combinations(m)  # [C, m]
    chance = np.clip(chances[uncertain], 1e-12, 1.0 - 1e-12)
    log_weight = np.where(combos, portable.log(chance), portable.log1p(-chance)).sum(axis=1)  # [C]
    columns = np.flatnonzero(observed)
    value = residual[columns]
    level = np.rint(value)
    usable = (np.abs(value - level) < INTEGER_TOLERANCE) & (np.abs(level) <= m)
    columns, level = columns[usable], level[usable].astype(np.int64)
    if columns.size:
        # P(the released synapses sum to each level), per combination and column, by
        # adding the released neurons' synapses one at a time (m additions never leave
        # the 2m + 1 levels, so np.roll never wraps mass around).
        sums = np.zeros((combos.shape[0], columns.size, 2 * m + 1))  # [C, cols, levels]
        sums[:, :, m] = 1.0
        for k, neuron in enumerate(uncertain):
            plus = excites[neuron, columns][:, None]  # [cols, 1]
            minus = inhibits[neuron, columns][:, None]
            added = sums * (1.0 - plus - minus) + np.roll(sums, 1, axis=2) * plus
            added += np.roll(sums, -1, axis=2) * minus
            sums = np.where(combos[:, k, None, None], added, sums)
        likelihood = sums[:, np.arange(columns.size), level + m]  # [C, cols]
        log_weight = log_weight + portable.log(np.maximum(likelihood, FLOOR)).sum(axis=1)
    weight = portable.exp(log_weight - log_weight.max())
    posterior = chances.copy()
    posterior[uncertain] = portable.matmul(weight / weight.sum(), combos)
    return posterior


@functools.cache
def _combinations(m: int) -> np.ndarray:
    """[2^m, m] bool, every combination of m releases (made once per m)."""
    combos = np.array(list(itertools.product((False, True), repeat=m)))
    combos.flags.writeable = False
    return combos


def settled_releases(
    chances: np.ndarray,
    residual: np.ndarray,
    observed: np.ndarray,
    excites: np.ndarray,
    inhibits: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(released [n] of 0/1, residual, observed [n])``: the evidence of one step for
    :meth:`~spikectl.planning.identify.ConnectivityEstimate.add` with the releases settled by
    :func:`release_posterior`. A release that stays unsettled withholds every column
    that one of its synapses may reach (probability above :data:`SETTLED`)."""
    posterior = release_posterior(chances, residual, observed, excites, inhibits)
    spiked = np.asarray(chances) > 0
    unsettled = spiked & (posterior > SETTLED) & (posterior < 1.0 - SETTLED)
    observed = np.asarray(observed, dtype=bool)
    if unsettled.any():
        reached = (excites[unsettled] + inhibits[unsettled]).max(axis=0) > SETTLED  # [n]
        observed = observed & ~reached
    released = (spiked & (posterior >= 0.5)).astype(np.float64)
    return released, residual, observed
