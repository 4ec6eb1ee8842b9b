"""The named identify-and-plan on suite v2's ``chr2`` TEST set, played once after the
choice on the validation set: the rows ``spikectl benchmark identify-and-plan --suite 2
--task chr2 --out ... --per-network ...`` writes, normalised against the do-nothing and
oracle references already in docs/results/suite-v2/identify-and-plan.csv (the CLI would
plan the oracle's 1 000 episodes again, ~1 300 CPU s, for the same numbers), and the
paired difference against the per-network returns there.

    python lab/results/iap-chr2/play_test_row.py OUT_DIR
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.named_row import play_named, write_rows
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells

TASK, SPLIT, VERSION = "chr2", "test", 2
OLD = Path("docs/results/suite-v2")


def old_rows() -> tuple[dict, np.ndarray]:
    with open(OLD / "identify-and-plan.csv") as handle:
        row = next(r for r in csv.DictReader(handle) if r["task"] == TASK)
    with open(OLD / "identify-and-plan-per-network.csv") as handle:
        per = [r for r in csv.DictReader(handle) if r["task"] == TASK]
    return row, np.array([float(r["return"]) for r in sorted(per, key=lambda r: int(r["context"]))])


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    old, old_returns = old_rows()
    result, composition, n_networks = play_named(TASK, SPLIT, VERSION)
    nothing, oracle = float(old["do_nothing"]), float(old["oracle"])
    row = dict(
        old,
        mean_return=f"{result.mean_return:.6f}",
        standard_error=f"{result.standard_error:.6f}",
        normalised=f"{suite.normalise(result.mean_return, nothing, oracle):.6f}",
        cpu_seconds=f"{result.cpu_seconds:.3f}",
        composition=composition,
    )
    write_rows(out, TASK, row, result, composition, VERSION)
    print(
        f"chr2 test: {result.mean_return:.4f} ± {result.standard_error:.4f} "
        f"(before {old_returns.mean():.4f}); {result.cpu_seconds:.1f} CPU s; {composition}"
    )
    print(
        f"new − before, network by network: {paired_difference_cells(result.returns - old_returns)}"
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
