"""Readers shared by the result folders' table scripts: a run's metrics.csv, its best
evaluation, and one task's returns in a per-network CSV (``spikectl benchmark
--per-network``). A script in a folder of lab/results imports them with

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    from result_tables import best, metrics, per_network
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
"""The committed data the scripts read (docs/results/FOLDER/)."""
PLANNER_TEST = RESULTS / "suite" / "identify-and-plan-per-network.csv"
"""Identify-and-plan (the named controller of the suite's leaderboard) on every task's
test networks, one row per network: what ``spikectl benchmark identify-and-plan --task
all --per-network`` writes (suite/run.sh), beside the suite's identify-and-plan.csv."""
PLANNER_VALIDATION = {"paper": 0.866, "n16": 0.799, "n32": 0.772}
"""The named identify-and-plan's mean return on each task's 100 validation networks
(bayes-identify's sweeps and particles/: the settings ``spikectl benchmark`` plays)."""


def metrics(folder: Path) -> dict[int, dict]:
    """A run's metrics.csv: its rows by episode."""
    with open(folder / "metrics.csv", newline="") as handle:
        return {int(row["episode"]): row for row in csv.DictReader(handle)}


def best(folder: Path) -> dict:
    """The evaluation row of the best validation return (the run's best model)."""
    return max(metrics(folder).values(), key=lambda row: float(row["val_return"]))


def per_network(path: Path, task: str) -> np.ndarray:
    """[100] the return on each network of ``task`` in a per-network CSV (of either
    split: the rows of contexts 0..99)."""
    with open(path, newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if row["task"] == task]
    if [int(row["context"]) for row in rows] != list(range(100)):
        raise ValueError(f"{path} lacks the 100 networks of {task}")
    return np.array([float(row["return"]) for row in rows])
