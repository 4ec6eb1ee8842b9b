"""The ``spikes`` composition with QMDP (the named controller now) on suite v2's
``spikes-only`` test networks, played once, network by network against what the named
controller scored there before (``before-test-per-network.csv``: the committed row
without QMDP, copied from docs/results/suite-v2 as it stood at commit ``cae9312``),
against doing nothing and the oracle, and against its own return with potentials
(the ``paper`` row).

    python lab/results/iap-spikes/compare.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "docs" / "results" / "iap-spikes"
SUITE2 = ROOT / "docs" / "results" / "suite-v2"


def returns(path: Path, task: str = "spikes-only") -> np.ndarray:
    """[1 000] the per-network returns of ``task`` in ``path``, in network order."""
    with open(path, newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if row["task"] == task]
    rows.sort(key=lambda row: int(row["context"]))
    return np.array([float(row["return"]) for row in rows])


def main() -> None:
    now = returns(DATA / "test-per-network.csv")
    error = now.std(ddof=1) / len(now) ** 0.5
    print(f"spikes-only test, with QMDP: {now.mean():.4f} ± {error:.4f}")
    references = {
        "the named controller before (no QMDP)": returns(DATA / "before-test-per-network.csv"),
        "doing nothing": returns(SUITE2 / "do-nothing-per-network.csv"),
        "the oracle": returns(SUITE2 / "oracle-per-network.csv"),
        "itself with potentials (paper)": returns(SUITE2 / "identify-and-plan-per-network.csv",
                                                  "paper"),
    }  # fmt: skip
    for name, reference in references.items():
        print(f"- {name} ({reference.mean():.4f}): {paired_difference_cells(now - reference)}")


if __name__ == "__main__":
    main()
