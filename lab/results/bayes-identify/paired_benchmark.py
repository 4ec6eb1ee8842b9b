"""Two `spikectl benchmark --per-network` CSVs of the same task and split, network by
network: the mean difference (new - old) with a 95% bootstrap interval over the networks
(10 000 resamples, seed 0) and how many networks each way.

    python lab/results/bayes-identify/paired_benchmark.py OLD.csv NEW.csv [--task T ...]
"""

from __future__ import annotations

import argparse
import csv

import numpy as np

from spikectl.experiments.stats import paired_difference_cells as paired_cells


def returns(path: str) -> dict[tuple[str, str], dict[int, float]]:
    table: dict[tuple[str, str], dict[int, float]] = {}
    with open(path, newline="") as handle:
        for row in csv.DictReader(handle):
            table.setdefault((row["task"], row["split"]), {})[int(row["context"])] = float(
                row["return"]
            )
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("--task", nargs="*", default=None)
    args = parser.parse_args()
    old, new = returns(args.old), returns(args.new)
    print("| task | split | old | new | new − old [95% CI] | better / worse networks |")
    print("|---|---|---:|---:|---|---|")
    for key in sorted(set(old) & set(new)):
        if args.task and key[0] not in args.task:
            continue
        a, b = old[key], new[key]
        if sorted(a) != sorted(b):
            raise SystemExit(f"{key[0]} {key[1]}: the two files hold different networks")
        difference = np.array([b[c] - a[c] for c in sorted(a)])
        print(
            f"| `{key[0]}` | {key[1]} | {np.mean(list(a.values())):.3f} | "
            f"{np.mean(list(b.values())):.3f} | {paired_cells(difference)} |"
        )


if __name__ == "__main__":
    main()
