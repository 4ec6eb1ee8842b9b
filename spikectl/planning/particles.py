"""The discrete posterior over each column of G at any size, kept as its likeliest hypotheses.

:class:`~spikectl.planning.discrete.DiscreteConnectivityEstimate` enumerates all
3^(n-1) columns G[:, j] in {-1, 0, +1}, which stops at n = 11. Most of them are never
told apart: a residual of neuron j only involves the neurons that released the step
before. :class:`ParticleConnectivityEstimate` therefore enumerates, per column, only
the entries some evidence has touched (a neuron that released while j was observed);
every other entry keeps its prior (the generator's connection probability for the
distance, excitatory with probability 0.8, Dale's law once the row's sign is known)
and is marginalised in closed form. When a neuron releases for the first time, each
hypothesis of the column splits into three (its prior weight on each value), and the
column keeps its :data:`MAX_HYPOTHESES` most probable hypotheses (a deterministic
particle filter: exact while the column has no more, and noise-free residuals are
integers, so most splits are ruled out by the next step). The likelihood of each
residual is the discrete estimate's: Gaussian at the residual noise, mixed with a
small broad outlier part. Same interface as the other estimates (``add``,
``posterior``, ``weights``, ``excitation_probability``, ``sample``, ``version``).
"""

from __future__ import annotations

import numpy as np

from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.planning import portable
from spikectl.planning.discrete import (
    _AGAINST_DALE,
    MIN_RESIDUAL_SD,
    SignMarginals,
    residual_log_likelihood,
)

MAX_HYPOTHESES = 2048
"""Hypotheses kept per column after each step's evidence; the estimate is exact while no
column holds more (n = 8's whole set is 3^7 = 2 187 per column)."""
_EXPANSION_LIMIT = 8 * MAX_HYPOTHESES  # pruned by weight while one step splits many entries
_NEGLIGIBLE = 40.0  # hypotheses this many nats below the best are dropped (e^-40)
_VALUES = np.array([-1, 0, 1], dtype=np.int8)


class ParticleConnectivityEstimate(SignMarginals):
    """Posterior over each column G[:, j] in {-1, 0, +1}^(n-1), on the touched entries.

    Args:
        n_neurons: observed neurons n.
        residual_sd: the residual noise in units of w_in (at least
            :data:`~spikectl.planning.discrete.MIN_RESIDUAL_SD` is assumed).
        max_hypotheses: hypotheses kept per column.
    """

    def __init__(
        self, n_neurons: int, residual_sd: float, max_hypotheses: int = MAX_HYPOTHESES
    ) -> None:
        if residual_sd <= 0:
            raise ValueError(f"residual_sd must be > 0, got {residual_sd}")
        if max_hypotheses < 3:
            raise ValueError(f"max_hypotheses must be >= 3, got {max_hypotheses}")
        n = self.n_neurons = n_neurons
        self.max_hypotheses = int(max_hypotheses)
        index = np.arange(n)
        probability = connection_probability(np.abs(index[:, None] - index[None, :]))
        np.fill_diagonal(probability, 0.0)  # no self-connections
        prior = np.stack(
            [probability * (1 - EXCITATORY_PROBABILITY), 1 - probability,
             probability * EXCITATORY_PROBABILITY]
        )  # [3 (value -1, 0, +1), n (pre), n (post)]  # fmt: skip
        with np.errstate(divide="ignore"):
            self._log_prior = portable.log(prior)  # Dale's law added once a row's sign is known
        self.residual_sd = max(float(residual_sd), MIN_RESIDUAL_SD)
        self.touched = np.zeros((n, n), dtype=bool)  # [post, pre]: entries enumerated
        self.hypotheses = [np.zeros((1, n), dtype=np.int8) for _ in range(n)]  # [M_j, pre]
        self.log_weights = [np.zeros(1) for _ in range(n)]  # [M_j]
        self._row_sign = np.zeros(n, dtype=np.int8)
        self.observations = 0
        self.version = 0
        """Counts the changes of the posterior (what may be cached against it)."""
        self._cache: tuple[np.ndarray, np.ndarray] | None = None
        self._marginal_cache: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """One step's evidence (as :meth:`ConnectivityEstimate.add`)."""
        if not observed.any() or not np.any(released):
            return
        released = np.asarray(released, dtype=np.float64)
        active = np.flatnonzero(released)  # the neurons in this step's sums
        for j in np.flatnonzero(observed):
            for pre in active[(active != j) & ~self.touched[j, active]]:
                self._split(j, pre)
            predicted = portable.matmul(self.hypotheses[j][:, active], released[active])  # [M_j]
            error = (residual[j] - predicted) / self.residual_sd
            self.log_weights[j] = self.log_weights[j] + residual_log_likelihood(
                error, self.residual_sd
            )
            self._prune(j, self.max_hypotheses)
        self.observations += int(observed.sum())
        self.version += 1
        self._cache = self._marginal_cache = None
        self._apply_dale()

    def _split(self, post: int, pre: int) -> None:
        """Enumerate G[pre, post]: every hypothesis of column ``post`` splits in three."""
        hypotheses, log_weights = self.hypotheses[post], self.log_weights[post]
        count = hypotheses.shape[0]
        split = np.repeat(hypotheses, 3, axis=0)  # [3 M, pre]
        split[:, pre] = np.tile(_VALUES, count)
        log_prior = self._log_prior[:, pre, post]  # [3], unnormalised
        self.hypotheses[post] = split
        self.log_weights[post] = (log_weights[:, None] + log_prior[None, :]).ravel()  # [3 M]
        self.touched[post, pre] = True
        self._prune(post, _EXPANSION_LIMIT)

    def _prune(self, post: int, keep: int) -> None:
        """Keep column ``post``'s ``keep`` likeliest hypotheses, dropping negligible ones."""
        log_weights = self.log_weights[post]
        log_weights = log_weights - log_weights.max()
        kept = log_weights > -_NEGLIGIBLE
        count = int(kept.sum())
        if count == log_weights.shape[0] <= keep:
            self.log_weights[post] = log_weights
            return
        if count > keep:
            kept = np.zeros_like(kept)
            # A stable sort, not argpartition: among equal weights the lowest indices stay,
            # whatever sorting kernel the CPU runs.
            kept[np.argsort(-log_weights, kind="stable")[:keep]] = True
        self.hypotheses[post] = self.hypotheses[post][kept]
        self.log_weights[post] = log_weights[kept]

    def _prior_marginals(self) -> tuple[np.ndarray, np.ndarray]:
        """(P(G = +1), P(G = -1)) [pre, post] of the untouched entries under the prior,
        with Dale's law where a row's sign is known."""
        prior = portable.exp(self._log_prior)  # [3, pre, post]
        prior /= prior.sum(axis=0, keepdims=True)
        return prior[2], prior[0]

    def _marginals(self) -> tuple[np.ndarray, np.ndarray]:
        """(P(G = +1), P(G = -1)), both [n (pre), n (post)], kept until the weights change."""
        if self._marginal_cache is None:
            self._marginal_cache = self._compute_marginals()
        return self._marginal_cache

    def _compute_marginals(self) -> tuple[np.ndarray, np.ndarray]:
        plus, minus = self._prior_marginals()
        for j in range(self.n_neurons):
            if not self.touched[j].any():
                continue
            weights = portable.exp(self.log_weights[j] - self.log_weights[j].max())
            weights /= weights.sum()  # [M_j]
            touched = self.touched[j]
            plus[touched, j] = portable.matmul(weights, self.hypotheses[j][:, touched] == 1)
            minus[touched, j] = portable.matmul(weights, self.hypotheses[j][:, touched] == -1)
        return plus, minus

    def _apply_dale(self) -> None:
        for row, sign in self._sign_rows():
            self._log_prior[_VALUES == -sign, row, :] += _AGAINST_DALE  # untouched, later splits
            for j in np.flatnonzero(self.touched[:, row]):
                against = self.hypotheses[j][:, row] == -sign  # [M_j]
                self.log_weights[j] = self.log_weights[j] + np.where(against, _AGAINST_DALE, 0.0)
            self._cache = self._marginal_cache = None

    def sample(
        self, known_sd: float, connection_uniforms: np.ndarray, sign_uniforms: np.ndarray
    ) -> np.ndarray:
        """K hypotheses int8 [K, n, n]: column j's touched entries one of its hypotheses,
        drawn by its weight with the uniform ``connection_uniforms[k, j, j]`` (the
        diagonal has no other use); each untouched entry a connection with its prior
        probability (``connection_uniforms[k, i, j]``) of its row's sign: the known one,
        else excitatory when ``sign_uniforms[k, i]`` < 0.8."""
        n = self.n_neurons
        plus, minus = self._prior_marginals()
        connected = connection_uniforms < plus + minus  # [K, pre, post]
        row_sign = np.where(sign_uniforms < EXCITATORY_PROBABILITY, 1, -1)  # [K, pre]
        row_sign = np.where(self._row_sign != 0, self._row_sign, row_sign)
        drawn = np.where(connected, row_sign[:, :, None], 0).astype(np.int8)  # [K, n, n]
        for j in range(n):
            touched = self.touched[j]
            if not touched.any():
                continue
            weights = portable.exp(self.log_weights[j] - self.log_weights[j].max())
            cumulative = np.cumsum(weights)
            cumulative /= cumulative[-1]
            choice = np.minimum(
                np.searchsorted(cumulative, connection_uniforms[:, j, j], side="right"),
                cumulative.shape[0] - 1,
            )  # [K]
            drawn[:, touched, j] = self.hypotheses[j][choice][:, touched]
        drawn[:, np.arange(n), np.arange(n)] = 0
        return drawn
