"""lab.planners.named_row plays the suite's row of the named identify-and-plan."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from lab.planners.named_row import play_named, write_rows

SUITE_ROWS = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite"


def test_play_named_gives_the_committed_suite_row(tmp_path):
    with open(SUITE_ROWS / "identify-and-plan.csv") as handle:
        row = next(r for r in csv.DictReader(handle) if r["task"] == "paper")
    result, composition, n_networks = play_named("paper", "test", 1)
    assert n_networks == int(row["contexts"]) == 100
    assert composition == "paper"
    assert result.mean_return == pytest.approx(float(row["mean_return"]), abs=5e-7)
    write_rows(tmp_path, "paper", {"task": "paper", "mean_return": "x"}, result, composition, 1)
    with open(tmp_path / "identify-and-plan-paper.csv") as handle:
        assert list(csv.DictReader(handle)) == [{"task": "paper", "mean_return": "x"}]
    with open(tmp_path / "identify-and-plan-paper-per-network.csv") as handle:
        rows = list(csv.DictReader(handle))
    with open(SUITE_ROWS / "identify-and-plan-per-network.csv") as handle:
        committed = [r for r in csv.DictReader(handle) if r["task"] == "paper"]
    assert [r["return"] for r in rows] == [r["return"] for r in committed]
    assert {r["composition"] for r in rows} == {"paper"}
