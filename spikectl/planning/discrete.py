"""Exact Bayesian identification over the discrete weights {-1, 0, +1} (small networks).

The weights are not real numbers: each G[i, j] is -1, 0 or +1 (Dale's law: one sign
per row). A residual over 20 mV is therefore an integer (noise-free) and most real
values a Gaussian posterior allows are impossible. :class:`DiscreteConnectivityEstimate`
keeps, for every postsynaptic neuron j, a weight on each of the 3^(n-1) possible
columns G[:, j] (the topology's prior: a connection with its distance's probability,
excitatory with probability 0.8), and multiplies in the likelihood of each residual.
Noise-free, two neurons that released together are told apart as soon as the sum is
0 or 2 (or a row's sign is known), where the Gaussian's ridge regression waits for
one to release alone. Each residual's likelihood is a Gaussian (the residual noise,
at least :data:`MIN_RESIDUAL_SD`) mixed with a small broad outlier part, so effects
the model does not know (hidden neurons, stochastic release, background input,
heterogeneous synapses) weaken the evidence instead of ruling out the truth.

The number of hypotheses grows as 3^(n-1): n = 8 keeps 2,187 per column;
:data:`MAX_COLUMN_HYPOTHESES` bounds it, and larger networks use the Gaussian
:class:`~spikectl.planning.identify.ConnectivityEstimate`. Both share one interface
(``add``, ``posterior``, ``weights``, ``excitation_probability``, ``sample``).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.planning import portable

MAX_COLUMN_HYPOTHESES = 3**10
"""Largest number of hypotheses per column (n <= 11 neurons)."""
MIN_RESIDUAL_SD = 0.1
"""Smallest residual noise (units of w_in) assumed: levels are 1 apart, so 0.1 still
decides between them, and a synapse 10 % off its nominal strength is not ruled out."""
OUTLIER_PROBABILITY = 0.01
"""Share of the likelihood given to residuals the model cannot explain."""
_OUTLIER_RANGE = 6.0  # the outlier part is uniform over +-3 w_in
_SIGN_KNOWN = 0.99  # a row's sign counts as known above this probability
_AGAINST_DALE = -30.0  # log-weight of a column that breaks a known row sign


def residual_log_likelihood(error: np.ndarray, residual_sd: float) -> np.ndarray:
    """log p(residual | hypothesis) for each standardised ``error`` (residual minus the
    hypothesis's prediction, over ``residual_sd``): Gaussian, mixed with the outlier part."""
    gaussian = (
        math.log1p(-OUTLIER_PROBABILITY) - 0.5 * error**2
        - math.log(residual_sd * math.sqrt(2 * math.pi))
    )  # fmt: skip
    return portable.logaddexp(gaussian, math.log(OUTLIER_PROBABILITY / _OUTLIER_RANGE))


def column_hypotheses_fit(n_neurons: int) -> bool:
    """True when exact identification fits a network of ``n_neurons``."""
    return 3 ** (n_neurons - 1) <= MAX_COLUMN_HYPOTHESES


class SignMarginals:
    """What a posterior over G in {-1, 0, +1} gives from its marginals: the mean and
    standard deviation, the weights to plan with and the chance of an excitatory synapse.
    A subclass provides ``_marginals()`` -> (P(G = +1), P(G = -1)), both [n (pre), n
    (post)], and clears ``_cache`` whenever they change."""

    _cache: tuple[np.ndarray, np.ndarray] | None
    _row_sign: np.ndarray  # [n] each row's known sign (Dale's law), 0 while unknown

    def _marginals(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _sign_rows(self) -> list[tuple[int, int]]:
        """The rows whose sign the marginals now know (beyond 0.99), as (row, sign), each
        recorded in ``_row_sign``: the subclass then rules out the other sign."""
        plus, minus = self._marginals()
        signs = np.where(plus.max(axis=1) > _SIGN_KNOWN, 1, 0)
        signs = np.where(minus.max(axis=1) > _SIGN_KNOWN, -1, signs)
        new = np.flatnonzero((signs != 0) & (self._row_sign == 0))
        self._row_sign[new] = signs[new]
        return [(int(row), int(signs[row])) for row in new]

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of G, both [n (pre), n (post)]."""
        if self._cache is None:
            plus, minus = self._marginals()
            mean = plus - minus
            sd = np.sqrt(np.maximum(plus + minus - mean**2, 0.0))
            self._cache = (mean, sd)
        return self._cache

    def weights(self, known_sd: float) -> tuple[np.ndarray, np.ndarray]:
        """(signs [n, n] to plan with, known [n, n]) as :meth:`ConnectivityEstimate.weights`:
        known entries (posterior sd below ``known_sd``) are the rounded mean, others 0."""
        mean, sd = self.posterior()
        known = sd < known_sd
        signs = np.where(known, np.clip(np.rint(mean), -1, 1), 0.0)
        return signs.astype(np.int8), known

    def excitation_probability(self, target: int, known_sd: float) -> np.ndarray:
        """[n] posterior probability that neuron i excites ``target``."""
        plus, _ = self._marginals()
        return plus[:, target]


class DiscreteConnectivityEstimate(SignMarginals):
    """Posterior over each column G[:, j] in {-1, 0, +1}^(n-1) (exact, per column).

    Columns are independent given the rows' signs; Dale's law couples them once a
    row's sign is known (then every column's hypotheses of the other sign for that
    row are all but ruled out).
    """

    def __init__(self, n_neurons: int, residual_sd: float) -> None:
        if residual_sd <= 0:
            raise ValueError(f"residual_sd must be > 0, got {residual_sd}")
        if not column_hypotheses_fit(n_neurons):
            raise ValueError(
                f"exact identification keeps 3^(n-1) hypotheses per column; n = {n_neurons} "
                f"is over the limit of {MAX_COLUMN_HYPOTHESES} (use ConnectivityEstimate)"
            )
        n = n_neurons
        values = np.array(list(itertools.product((-1, 0, 1), repeat=n - 1)), dtype=np.int8)
        index = np.arange(n)
        probability = connection_probability(np.abs(index[:, None] - index[None, :]))  # [pre, post]
        self.n_neurons = n
        self.hypotheses = np.zeros((n, values.shape[0], n), dtype=np.int8)  # [post, M, pre]
        self.log_weights = np.zeros((n, values.shape[0]))  # [post, M]
        for j in range(n):
            pre = np.delete(index, j)
            self.hypotheses[j][:, pre] = values
            p = probability[pre, j]  # [n - 1]
            log_prior = np.stack(
                [portable.log(p * (1 - EXCITATORY_PROBABILITY)), portable.log1p(-p),
                 portable.log(p * EXCITATORY_PROBABILITY)]
            )  # [3 (value -1, 0, +1), n - 1]  # fmt: skip
            self.log_weights[j] = log_prior[values + 1, np.arange(n - 1)].sum(axis=1)
        self.residual_sd = max(float(residual_sd), MIN_RESIDUAL_SD)
        self._row_sign = np.zeros(n, dtype=np.int8)
        self.observations = 0
        self.version = 0
        """Counts the changes of the posterior (what may be cached against it)."""
        self._cache: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """One step's evidence (as :meth:`ConnectivityEstimate.add`)."""
        if not observed.any() or not np.any(released):
            return
        predicted = portable.matmul(self.hypotheses[observed], released)  # [k, M]
        error = (residual[observed, None] - predicted) / self.residual_sd
        self.log_weights[observed] += residual_log_likelihood(error, self.residual_sd)
        self.log_weights[observed] -= self.log_weights[observed].max(axis=1, keepdims=True)
        self.observations += int(observed.sum())
        self.version += 1
        self._cache = None
        self._apply_dale()

    def _marginals(self) -> tuple[np.ndarray, np.ndarray]:
        """(P(G = +1), P(G = -1)), both [n (pre), n (post)]."""
        weights = portable.exp(self.log_weights - self.log_weights.max(axis=1, keepdims=True))
        weights /= weights.sum(axis=1, keepdims=True)  # [post, M]
        plus = portable.matmul(weights[:, None, :], self.hypotheses == 1)[:, 0, :].T
        minus = portable.matmul(weights[:, None, :], self.hypotheses == -1)[:, 0, :].T
        return plus, minus

    def _apply_dale(self) -> None:
        for row, sign in self._sign_rows():
            against = self.hypotheses[:, :, row] == -sign  # [post, M]
            self.log_weights += np.where(against, _AGAINST_DALE, 0.0)
            self._cache = None

    def sample(
        self, known_sd: float, connection_uniforms: np.ndarray, sign_uniforms: np.ndarray
    ) -> np.ndarray:
        """K hypotheses int8 [K, n, n], column j of hypothesis k drawn from its posterior
        by the uniform ``connection_uniforms[k, 0, j]`` (``sign_uniforms`` is unused:
        signs are part of each column's hypotheses)."""
        weights = portable.exp(self.log_weights - self.log_weights.max(axis=1, keepdims=True))
        cumulative = np.cumsum(weights, axis=1)
        cumulative /= cumulative[:, -1:]  # [post, M]
        uniforms = connection_uniforms[:, 0, :]  # [K, post]
        k, n = uniforms.shape[0], self.n_neurons
        drawn = np.empty((k, n, n), dtype=np.int8)
        for j in range(n):
            choice = np.minimum(np.searchsorted(cumulative[j], uniforms[:, j], side="right"),
                                cumulative.shape[1] - 1)  # fmt: skip
            drawn[:, :, j] = self.hypotheses[j, choice]  # [K, pre]
        return drawn
