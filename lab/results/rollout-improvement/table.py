"""The table of README.md from per-network.csv: each variant against the named
controller on the same networks, network by network.

    python lab/results/rollout-improvement/table.py
"""

from __future__ import annotations

import csv
from collections import defaultdict
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

BASE = "named controller (base)"


def main() -> None:
    returns: dict = defaultdict(dict)
    data = Path(__file__).resolve().parents[3] / "docs" / "results" / "rollout-improvement"
    with open(data / "per-network.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            returns[row["variant"]][(row["split"], int(row["context"]))] = float(row["return"])
    print("| variant | networks | mean | named controller | − named [95% CI] | better / worse |")
    print("|---|---|---:|---:|---|---|")
    for variant, played in returns.items():
        if variant == BASE:
            continue
        keys = sorted(played)
        splits = " + ".join(sorted({split for split, _ in keys}))
        new = np.array([played[key] for key in keys])
        old = np.array([returns[BASE][key] for key in keys])
        print(f"| {variant} | {splits} ({len(keys)}) | {new.mean():.3f} | {old.mean():.3f} | "
              f"{paired_difference_cells(new - old)} |")  # fmt: skip


if __name__ == "__main__":
    main()
