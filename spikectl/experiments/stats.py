"""Aggregate statistics over seeds: interquartile mean and stratified-bootstrap intervals.

This is the method of rliable (Agarwal et al., 2021, "Deep RL at the edge of the
statistical precipice") in a few lines of NumPy, because rliable itself does not work
with pandas 3:

* :func:`iqm` is the interquartile mean: the mean of the middle 50% of the scores,
  trimmed exactly as ``scipy.stats.trim_mean(x, 0.25)`` (``int(0.25 * n)`` scores cut
  from each end). It is robust to one outlying seed, yet uses more of the data than
  the median.
* :func:`bootstrap_ci` is a percentile interval of a statistic under the *stratified*
  bootstrap (rliable's ``StratifiedBootstrap``): the runs of every task (or
  condition) are resampled with replacement independently of the other tasks, so
  each resample keeps the number of runs per task, and the statistic is computed on
  all resampled scores pooled.

All randomness comes from an explicit ``numpy.random.Generator`` (or a seed).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import numpy as np

Statistic = Callable[[np.ndarray], float]


class Interval(NamedTuple):
    """A point estimate and its confidence interval ``[low, high]``."""

    estimate: float
    low: float
    high: float


def _scores(values, name: str = "values") -> np.ndarray:
    array = np.asarray(values, dtype=float).ravel()
    if array.size == 0:
        raise ValueError(f"{name} is empty: need at least one score")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or infinite scores: {array}")
    return array


def iqm(values) -> float:
    """Interquartile mean of all ``values`` (any shape, flattened).

    ``int(0.25 * n)`` of the lowest and as many of the highest scores are dropped and
    the rest averaged, as ``scipy.stats.trim_mean(values, 0.25, axis=None)``; with
    fewer than 4 scores nothing is dropped (the plain mean).
    """
    array = np.sort(_scores(values))
    cut = int(0.25 * array.size)
    return float(array[cut : array.size - cut].mean())


def _strata(scores) -> list[np.ndarray]:
    """The runs of each task: a 1-D array is one task; a 2-D array is [runs, tasks]
    (rliable's layout); a mapping or a sequence of 1-D arrays gives one task each
    (their numbers of runs may differ)."""
    if isinstance(scores, Mapping):
        items = [(f"task {key!r}", value) for key, value in scores.items()]
    elif isinstance(scores, np.ndarray) or (
        isinstance(scores, Sequence) and all(np.ndim(item) == 0 for item in scores)
    ):
        array = np.asarray(scores, dtype=float)
        if array.ndim == 1:
            items = [("scores", array)]
        elif array.ndim == 2:
            items = [(f"task {k}", array[:, k]) for k in range(array.shape[1])]
        else:
            raise ValueError(f"scores must be 1-D or 2-D [runs, tasks], got shape {array.shape}")
    else:
        items = [(f"task {k}", value) for k, value in enumerate(scores)]
    if not items:
        raise ValueError("scores is empty: need at least one task with one run")
    return [_scores(value, name) for name, value in items]


def bootstrap_ci(
    scores,
    statistic: Statistic = iqm,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    rng: np.random.Generator | int | None = 0,
) -> Interval:
    """Point estimate and percentile confidence interval of ``statistic`` under the
    stratified bootstrap over runs (seeds).

    Args:
        scores: the runs' scores: a 1-D array (one task), a 2-D array [runs, tasks],
            or a mapping / sequence of 1-D arrays, one per task.
        statistic: maps the pooled 1-D array of all scores to a number (default
            :func:`iqm`; ``np.mean``, ``np.median`` work too).
        n_resamples: number of bootstrap resamples.
        confidence: coverage of the interval, in (0, 1).
        rng: a ``numpy.random.Generator`` or a seed; the same seed gives the same
            interval.

    Returns:
        ``Interval(estimate, low, high)``: the statistic of the original scores and the
        ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` quantiles of its
        bootstrap distribution. Constant scores give a zero-width interval.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie strictly between 0 and 1, got {confidence}")
    if int(n_resamples) != n_resamples or n_resamples < 1:
        raise ValueError(f"n_resamples must be a positive integer, got {n_resamples}")
    strata = _strata(scores)
    generator = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    estimate = float(statistic(np.concatenate(strata)))
    # Each stratum is resampled on its own: [n_resamples, runs of that task] indices.
    resampled = np.concatenate(
        [runs[generator.integers(0, runs.size, size=(int(n_resamples), runs.size))]
         for runs in strata],
        axis=1,
    )  # fmt: skip
    distribution = np.array([statistic(row) for row in resampled], dtype=float)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(distribution, [tail, 1.0 - tail])
    return Interval(estimate, float(low), float(high))


def paired_difference_cells(difference, n_resamples: int = 10_000, rng: int = 0) -> str:
    """Two table cells for per-network differences ``new - old`` of two controllers on
    the same networks: ``mean [low, high] | better / worse``, the mean with its 95%
    bootstrap interval over the networks and how many networks each way."""
    difference = _scores(difference, "difference")
    interval = bootstrap_ci(difference, statistic=np.mean, n_resamples=n_resamples, rng=rng)
    return (
        f"{interval.estimate:+.3f} [{interval.low:+.3f}, {interval.high:+.3f}] | "
        f"{(difference > 1e-12).sum()} / {(difference < -1e-12).sum()}"
    )


def summarise(
    values,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    rng: np.random.Generator | int | None = 0,
) -> dict[str, float]:
    """Mean, standard deviation (over seeds, ``ddof=0`` as ``np.std``), IQM and the
    IQM's stratified-bootstrap interval of one condition's per-seed scores."""
    array = _scores(values)
    interval = bootstrap_ci(array, iqm, n_resamples, confidence, rng)
    return {
        "n": int(array.size),
        "mean": float(array.mean()),
        "std": float(array.std()),
        "iqm": interval.estimate,
        "iqm_low": interval.low,
        "iqm_high": interval.high,
    }
