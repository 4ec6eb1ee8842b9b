"""The real-time identify-and-plan record's scripts (lab/results/realtime-iap): each form
plays the composition it names, a partial run keeps the other forms' rows, and the
tables render from the committed files."""

from __future__ import annotations

import csv

from lab.planners import TargetPathsOnly
from lab.scripts import load_script
from spikectl.planning.named import REALTIME_WIDTH


def script(name: str):
    return load_script("realtime-iap", name)


def test_each_form_plays_its_composition():
    measure = script("measure")
    contexts, extensions = measure.split_set("n16", "validation")
    fast = measure.controller("fast", contexts, extensions).composition
    realtime = measure.controller("realtime", contexts, extensions).composition
    cut = measure.controller("target-paths", contexts, extensions).composition
    assert (fast.name, realtime.name, cut.name) == (
        "paper-16-fast", "paper-16-realtime", "paper-16-fast-target-paths")  # fmt: skip
    assert realtime.decision.width == REALTIME_WIDTH and fast.decision.width == 32
    assert isinstance(cut.decision, TargetPathsOnly) and cut.decision.width == 32


def test_a_partial_play_keeps_the_other_forms_rows(tmp_path):
    measure = script("measure")
    measure.play("validation", tmp_path, ["paper"], ["fast"])
    with open(tmp_path / "validation-per-network.csv", newline="") as handle:
        fast = [row for row in csv.DictReader(handle)]
    measure.play("validation", tmp_path, ["paper"], ["realtime"])
    with open(tmp_path / "validation-per-network.csv", newline="") as handle:
        both = [row for row in csv.DictReader(handle)]
    assert both[: len(fast)] == fast and len(both) == 2 * len(fast) == 200
    assert [row["form"] for row in both[len(fast):]] == ["realtime"] * 100
    with open(tmp_path / "validation.csv", newline="") as handle:
        assert [row["form"] for row in csv.DictReader(handle)] == ["fast", "realtime"]


def test_the_tables_render_from_the_committed_files(capsys):
    script("table").main()
    out = capsys.readouterr().out
    assert "| n16 | 0.782 | 0.785 | 0.784 |" in out  # the test split's three forms
    assert "| n16 | 12 | 0.764 |" in out and "| 16 | realtime | 1200 |" in out
