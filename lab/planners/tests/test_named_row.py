"""lab.planners.named_row plays the suite's row of the named identify-and-plan."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from lab.planners.named_row import play_named

SUITE_ROWS = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite"


def test_play_named_gives_the_committed_suite_row():
    with open(SUITE_ROWS / "identify-and-plan.csv") as handle:
        row = next(r for r in csv.DictReader(handle) if r["task"] == "paper")
    result, composition, n_networks = play_named("paper", "test", 1)
    assert n_networks == int(row["contexts"]) == 100
    assert composition == "paper"
    assert result.mean_return == pytest.approx(float(row["mean_return"]), abs=5e-7)
