"""lab.planners.named_row plays the suite's row of the named identify-and-plan."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from lab.planners.named_row import play_named, play_named_part, write_rows

SUITE_ROWS = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite"
SUITE_V2_ROWS = SUITE_ROWS.parent / "suite-v2"


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


def test_a_part_plays_its_networks_as_the_whole_set_does():
    """Networks 998 and 999 of ``rig``'s test set played alone give the committed returns
    of the whole set's play: their background input (sub-environment i seeded
    ``env_seed + i``) and the planner's drawn networks (copy i seeded ``i``) are theirs."""
    with open(SUITE_V2_ROWS / "identify-and-plan-per-network.csv") as handle:
        committed = {int(r["context"]): r["return"] for r in csv.DictReader(handle)
                     if r["task"] == "rig"}  # fmt: skip
    returns, cpu, composition = play_named_part("rig", range(998, 1000))
    assert composition == "rig" and cpu > 0
    assert [repr(float(value)) for value in returns] == [committed[998], committed[999]]
