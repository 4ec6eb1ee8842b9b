"""Every n16 / n32 setting of the validation sweeps against the QMDP row the named
controller played before (sweep 7's ``{"gamble_networks": 16}``), network by network:
mean difference with a 95% bootstrap interval (10 000 resamples, seed 0).

    python lab/results/bayes-identify/paired_validation.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from paired_benchmark import paired_cells  # beside this script

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "bayes-identify"
BEFORE = '{"gamble_networks": 16}'


def main() -> None:
    returns: dict[tuple[str, str], dict[int, float]] = {}
    for path in sorted(HERE.glob("validation-sweep*-per-network.csv")):
        with open(path, newline="") as handle:
            for row in csv.DictReader(handle):
                key = (row["task"], row["settings"])
                returns.setdefault(key, {})[int(row["context"])] = float(row["return"])
    print("| task | setting | mean return | against QMDP before [95% CI] | better / worse |")
    print("|---|---|---:|---|---|")
    for task in ("n16", "n32"):
        before = returns[(task, BEFORE)]
        for (name, settings), after in sorted(returns.items()):
            if name != task or settings == BEFORE:
                continue
            difference = np.array([after[c] - before[c] for c in sorted(before)])
            print(
                f"| `{task}` | `{settings}` | {np.mean(list(after.values())):.3f} | "
                f"{paired_cells(difference)} |"
            )


if __name__ == "__main__":
    main()
