"""identify-and-plan's Gaussian posterior of the target's column alone, as a belief the
amortised controller can read (``AmortisedController(GaussianColumn(), params)``): the
research record's "exact column" controller (docs/results/column-belief), which asks
whether that controller is held back by its trained belief or by its one-column rule."""

from __future__ import annotations

import math

import numpy as np

from spikectl.agents.amortised_belief import FEATURES

NOISE_FREE_SD = 0.01
"""The residual noise of one noise-free observation in units of w_in, as
identify-and-plan's estimate assumes it (``spikectl.planning.identify.NOISE_FREE_SD``)."""
EXCITATORY = 0.8
"""The generator's probability that a connection is excitatory."""
UNTOUCHED = 0.9
"""An entry whose posterior sd is still this fraction of the prior's reads as the prior,
as identify-and-plan's ``ConnectivityEstimate.entry_probabilities`` reads it."""
DECIMALS = 9
"""Probabilities are kept to this many decimals (ties, :meth:`GaussianColumn._probabilities`)."""
RELEASED_BEFORE, TARGET_RESIDUAL, TARGET_OBSERVED = (
    FEATURES.index(name) for name in ("released_before", "target_residual", "target_observed")
)


class GaussianColumn:
    """identify-and-plan's Gaussian posterior (``ConnectivityEstimate``) of the target's
    column alone, behind the interface ``AmortisedController`` reads a belief by:
    ``reset(prior [n])``, ``step(row [n, F]) -> log-probabilities [n, 3]`` (none,
    excitatory, inhibitory).

    The column has precision ``diag(1 / prior) + X^T X / s^2`` and mean ``precision^-1
    X^T y / s^2``, X the release vectors of the steps before each observation of the
    target and y its residuals over 20 mV (the row's ``released_before``,
    ``target_residual`` and ``target_observed``)."""

    def reset(self, prior: np.ndarray) -> None:
        self.prior = np.asarray(prior, dtype=np.float64)  # [n], 0 for the target itself
        variance = np.where(self.prior > 0, self.prior, 1e-9)
        self.prior_sd = np.sqrt(variance)
        self.precision = np.diag(1.0 / variance)  # [n, n]
        self.moment = np.zeros(self.prior.shape[0])  # [n]
        self.probabilities = self._probabilities()

    def step(self, row: np.ndarray) -> np.ndarray:
        released = row[:, RELEASED_BEFORE].astype(np.float64)  # [n]
        if row[0, TARGET_OBSERVED] > 0 and released.any():
            weight = 1.0 / NOISE_FREE_SD**2
            self.precision += np.outer(released, released) * weight
            self.moment += float(row[0, TARGET_RESIDUAL]) * released * weight
            self.probabilities = self._probabilities()
        return np.log(np.clip(self.probabilities, 1e-300, 1.0))

    def _probabilities(self) -> np.ndarray:
        """[n, 3] P(none), P(+1), P(-1) of each entry of the column."""
        lower = np.linalg.cholesky(self.precision)
        inverse_lower = np.linalg.inv(lower)
        covariance = inverse_lower.T @ inverse_lower  # [n, n]
        mean = covariance @ self.moment
        sd = np.sqrt(np.diag(covariance))
        scale = sd * math.sqrt(2.0)
        excites = 0.5 * np.array([math.erfc(x) for x in (0.5 - mean) / scale])
        inhibits = 0.5 * np.array([math.erfc(x) for x in (0.5 + mean) / scale])
        untouched = sd >= UNTOUCHED * self.prior_sd
        plus = np.where(untouched, self.prior * EXCITATORY, excites)
        minus = np.where(untouched, self.prior * (1.0 - EXCITATORY), inhibits)
        probabilities = np.stack([np.clip(1.0 - plus - minus, 0.0, 1.0), plus, minus], axis=1)
        # Rounded so that inputs the evidence has made equally likely tie exactly (the
        # lower index wins), whatever the inverse's last bits on this CPU.
        return np.round(probabilities, DECIMALS)
