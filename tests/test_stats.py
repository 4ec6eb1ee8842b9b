"""Interquartile mean and stratified-bootstrap intervals (spikectl.experiments.stats)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from spikectl.experiments.stats import bootstrap_ci, iqm, summarise


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        (range(1, 9), 4.5),  # drop 1, 2 and 7, 8: mean of 3, 4, 5, 6
        ([1, 2, 3], 2.0),  # int(0.75) = 0: nothing dropped
        ([5, 1, 100, 3], 4.0),  # one cut from each end: mean of 3, 5
        ([200, 1, 2, 3, 4, 5, 6, 100, -100], 4.0),  # int(2.25) = 2 cut: mean of 2..6
        ([[1, 2], [3, 4]], 2.5),  # any shape, flattened
    ],
)
def test_iqm_hand_cases(values, expected):
    data = np.asarray(list(values) if isinstance(values, range) else values, dtype=float)
    assert iqm(data) == pytest.approx(expected)


def test_iqm_matches_scipy_trim_mean():
    rng = np.random.default_rng(3)
    for size in range(1, 30):
        values = rng.normal(size=size)
        assert iqm(values) == pytest.approx(stats.trim_mean(values, 0.25))


def test_iqm_rejects_empty_and_nan():
    with pytest.raises(ValueError, match="empty"):
        iqm([])
    with pytest.raises(ValueError, match="NaN"):
        iqm([1.0, float("nan")])


def test_ci_contains_estimate_and_is_deterministic():
    scores = np.random.default_rng(0).normal(0.7, 0.05, size=10)
    interval = bootstrap_ci(scores, rng=np.random.default_rng(1))
    assert interval.estimate == pytest.approx(iqm(scores))
    assert interval.low <= interval.estimate <= interval.high
    assert interval.low < interval.high
    assert bootstrap_ci(scores, rng=np.random.default_rng(1)) == interval
    assert bootstrap_ci(scores, rng=7) == bootstrap_ci(scores, rng=7)
    assert bootstrap_ci(scores, rng=7) != bootstrap_ci(scores, rng=8)


def test_ci_narrows_with_more_seeds():
    rng = np.random.default_rng(0)
    few = rng.normal(0.7, 0.05, size=5)
    many = rng.normal(0.7, 0.05, size=200)
    width_few = np.subtract(*bootstrap_ci(few, np.mean, rng=0)[2:0:-1])
    width_many = np.subtract(*bootstrap_ci(many, np.mean, rng=0)[2:0:-1])
    assert 0 < width_many < width_few / 2


def test_constant_scores_give_zero_width():
    assert tuple(bootstrap_ci([0.6] * 5, rng=0)) == pytest.approx((0.6, 0.6, 0.6))
    assert tuple(bootstrap_ci({"a": [0.3, 0.3], "b": [0.9]}, np.mean, rng=0)) == pytest.approx(
        (0.5, 0.5, 0.5)
    )


def test_resampling_is_stratified_per_task():
    # Task a always scores 0 and task b always 1: a stratified resample keeps 3 runs of a
    # and 1 of b, so the mean is 0.25 in every resample; pooled resampling would vary.
    interval = bootstrap_ci({"a": [0.0, 0.0, 0.0], "b": [1.0]}, np.mean, rng=0)
    assert tuple(interval) == pytest.approx((0.25, 0.25, 0.25))
    matrix = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])  # [runs, tasks]
    assert tuple(bootstrap_ci(matrix, np.mean, rng=0)) == pytest.approx((0.5, 0.5, 0.5))


def test_percentile_interval_matches_a_hand_bootstrap():
    scores = np.array([0.1, 0.4, 0.5, 0.9])
    interval = bootstrap_ci(scores, np.mean, n_resamples=500, confidence=0.9, rng=3)
    rng = np.random.default_rng(3)
    means = scores[rng.integers(0, 4, size=(500, 4))].mean(axis=1)
    assert interval.low == pytest.approx(np.quantile(means, 0.05))
    assert interval.high == pytest.approx(np.quantile(means, 0.95))


@pytest.mark.parametrize("confidence", [0.0, 1.0, 95, -0.5])
def test_bad_confidence_is_an_error(confidence):
    with pytest.raises(ValueError, match="confidence"):
        bootstrap_ci([1.0, 2.0], confidence=confidence)


def test_bad_input_is_an_error():
    with pytest.raises(ValueError, match="empty"):
        bootstrap_ci([])
    with pytest.raises(ValueError, match="empty"):
        bootstrap_ci({})
    with pytest.raises(ValueError, match="empty"):
        bootstrap_ci({"a": [1.0], "b": []})
    with pytest.raises(ValueError, match="n_resamples"):
        bootstrap_ci([1.0], n_resamples=0)


def test_summarise():
    summary = summarise([0.2, 0.4, 0.6, 0.8], rng=0)
    assert summary["n"] == 4
    assert summary["mean"] == pytest.approx(0.5)
    assert summary["std"] == pytest.approx(np.std([0.2, 0.4, 0.6, 0.8]))
    assert summary["iqm"] == pytest.approx(0.5)
    assert summary["iqm_low"] <= 0.5 <= summary["iqm_high"]


def test_paired_difference_cells_give_the_mean_its_interval_and_the_counts_each_way():
    from spikectl.experiments.stats import paired_difference_cells

    assert paired_difference_cells([0.02] * 5) == "+0.020 [+0.020, +0.020] | 5 / 0"
    cells = paired_difference_cells([0.1, 0.1, -0.1, 0.0])
    estimate, counts = cells.split(" | ")
    assert estimate.startswith("+0.025 [") and counts == "2 / 1"
    low, high = (float(x) for x in estimate[8:-1].split(", "))
    assert -0.1 <= low < 0.025 < high <= 0.1
