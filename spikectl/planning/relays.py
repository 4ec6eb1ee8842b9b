"""Relays through hidden neurons: learned as two-step effects, planned as virtual neurons.

A hidden neuron h is simulated but neither observed nor stimulable. When an observed
neuron i excites it, a release of i at step t fires h at t + 1 (one excitatory input from
rest reaches the threshold exactly), and h's release moves h's own postsynaptic neurons
at t + 2: to the observer, i acts on them *two* steps later. The paper's model, which
:class:`~spikectl.planning.identify.ConnectivityEstimate` learns, has no such effect: the
estimate credits it to whatever observed neuron released at t + 1, or ignores it, and a
target driven only through hidden neurons looks unreachable.

:class:`RelayConnectivityEstimate` regresses each residual on the releases of both the
step before and the one before that,

    residual_j(t) = sum_i G[i, j] released_i(t-1) + sum_i L[i, j] released_i(t-2),

with L, the relay weights, drawn from a narrow prior (:data:`RELAY_PRIOR_VARIANCE`:
most pairs have no relay, and a wide prior takes the credit for direct synapses whose
releases always follow another's). :func:`relay_weights` plans with L by giving every
observed neuron i a virtual relay neuron v_i (i excites v_i, v_i acts on the observed
neurons with L's known entries), and :func:`relay_state` adds the virtual neurons' state,
which follows from the observed releases alone: v_i fires one step after each release of
i (i releases at most every 5 steps, so v_i is never refractory or out of vesicles then).
A hidden neuron that relays for several observed neurons is several virtual ones, each
with its own vesicles: the plan may count on two relays that share one, and then the
target's spike does not come (a surprise, and the policy re-plans).
"""

from __future__ import annotations

import numpy as np

from spikectl.neuron.kernel import SINCE_RELEASE_CAP
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import SimulatorState
from spikectl.planning import portable
from spikectl.planning.identify import ConnectivityEstimate, add_evidence

RELAY_PRIOR_VARIANCE = 0.02
"""The prior variance of each relay weight L[i, j] (in units of w_in squared), chosen on
the ``hidden25`` train and validation sets (docs/results/hidden-relays): 0.01 to 0.03
score alike, 0.05 and wider lose the direct synapses to the relays."""


class RelayConnectivityEstimate(ConnectivityEstimate):
    """The Gaussian posterior over G (:class:`ConnectivityEstimate`) learned together
    with the relay weights L [n, n] (units of w_in): column j regresses its residuals
    on ``[released(t-1), released(t-2)]`` ([2n] regressors), prior mean 0 and variance
    the topology's connection probabilities for G, ``relay_variance`` for L.
    :meth:`posterior` and everything read from it are G's; :meth:`relays` is L's."""

    def __init__(
        self, n_neurons: int, residual_sd: float, relay_variance: float = RELAY_PRIOR_VARIANCE
    ) -> None:
        if not relay_variance > 0:
            raise ValueError(f"relay_variance must be > 0, got {relay_variance!r}")
        super().__init__(n_neurons, residual_sd)
        n = n_neurons
        direct = self.precision  # [post, pre, pre]
        self.precision = np.zeros((n, 2 * n, 2 * n))  # [post, (pre, pre two steps back)²]
        self.precision[:, :n, :n] = direct
        lagged = np.arange(n, 2 * n)
        self.precision[:, lagged, lagged] = 1.0 / relay_variance
        self.moment = np.zeros((n, 2 * n))  # [post, 2n]
        self._released_before = np.zeros(n)  # released(t-2) at the next add()
        self._relays: tuple[np.ndarray, np.ndarray] | None = None
        self._cache = None

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        """One step's evidence, as :meth:`ConnectivityEstimate.add` (called every step:
        the releases two steps back are the ones of the call before)."""
        regressors = np.concatenate([released, self._released_before])  # [2n]
        self._released_before = np.asarray(released, dtype=np.float64).copy()
        if not observed.any() or not regressors.any():
            return
        add_evidence(self.precision, self.moment, observed, regressors, residual,
                     self._noise_precision)  # [2n, 2n], [2n] per column
        self.observations += int(observed.sum())
        self.version += 1
        self._cache = None
        self._parts = None
        self._relays = None
        self._weights.clear()

    def _solve(self) -> None:
        n = self.n_neurons
        covariance = portable.spd_inverse(self.precision)  # [post, 2n, 2n]
        mean = portable.matmul(covariance, self.moment[:, :, None])[:, :, 0]  # [post, 2n]
        sd = np.sqrt(np.diagonal(covariance, axis1=1, axis2=2))  # [post, 2n]
        self._cache = (mean[:, :n].T.copy(), sd[:, :n].T.copy())  # G: [pre, post]
        self._relays = (mean[:, n:].T.copy(), sd[:, n:].T.copy())  # L: [pre, post]

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of G, both [n (pre), n (post)]."""
        if self._cache is None:
            self._solve()
        return self._cache

    def column(self, post: int) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of column ``post`` of G, both [n (pre)]."""
        mean, sd = self.posterior()
        return mean[:, post].copy(), sd[:, post].copy()

    def relays(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of the relay weights L, both [n (pre), n (post)]:
        L[i, j] is i's effect on j two steps after i's release."""
        if self._relays is None:
            self._solve()
        return self._relays

    def relay_signs(self, known_sd: float) -> np.ndarray:
        """int8 [n, n] the relay weights to plan with: known ones (standard deviation
        below ``known_sd``) rounded to {-1, 0, +1}, the others 0."""
        mean, sd = self.relays()
        return np.where(sd < known_sd, np.clip(np.rint(mean), -1, 1), 0).astype(np.int8)


def relay_weights(weights: np.ndarray, relays: np.ndarray) -> np.ndarray:
    """[2n, 2n] the network to plan on: ``weights`` [n, n] among the observed neurons,
    each observed neuron i exciting its virtual relay neuron n + i, which acts on the
    observed neurons with ``relays`` [n, n] (L). The dtype is ``weights``'."""
    n = weights.shape[0]
    planned = np.zeros((2 * n, 2 * n), dtype=weights.dtype)
    planned[:n, :n] = weights
    planned[np.arange(n), n + np.arange(n)] = 1
    planned[n:, :n] = relays
    return planned


def relay_state(state: SimulatorState, params: NeuronParams) -> SimulatorState:
    """[1, 2n] ``state`` ([1, n], the observed neurons after a step) with the state of
    their virtual relay neurons appended: v_i spiked and released at the last step
    where i released the step before (then refractory), and its vesicles were last
    released one step after i's; else at rest with no release on record (a release of
    i at the last step fires v_i at the next, through the weights)."""
    since = state.steps_since_release  # [1, n] steps since each i's last release
    fired = since == 1  # [1, n] v_i fired at the last step
    relayed = (since >= 1) & (since < SINCE_RELEASE_CAP)  # v_i has released since
    relay_since = np.where(relayed, since - 1, SINCE_RELEASE_CAP).astype(since.dtype)
    relay_refractory = np.where(fired, params.refractory_steps, 0).astype(
        state.refractory_left.dtype
    )
    return SimulatorState(
        np.concatenate([state.voltage_mV, np.full_like(state.voltage_mV, params.v_rest_mV)], 1),
        np.concatenate([state.refractory_left, relay_refractory], 1),
        np.concatenate([since, relay_since], 1),
        np.concatenate([state.released, fired], 1),
    )  # each [1, 2n]
