"""The belief policy's tables from the committed CSVs (docs/results/belief-policy).

    python lab/results/belief-policy/table.py

Prints, for each split in the per-network CSVs (``validation.csv``, ``test.csv``), each
controller's mean return per task and its paired network-by-network difference against
the fixed rule on the same belief and against identify-and-plan (95 % bootstrap interval,
networks better / worse); identify-and-plan's test rows are suite v1's committed ones,
its validation rows those of docs/results/column-belief.
"""

from __future__ import annotations

import csv
from collections import defaultdict
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import bootstrap_ci

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "docs" / "results" / "belief-policy"
RESULTS = ROOT / "docs" / "results"
NAMED = {"test": RESULTS / "suite" / "identify-and-plan-per-network.csv",
         "validation": RESULTS / "column-belief" / "validation-per-network.csv"}  # fmt: skip
TASKS = ("paper", "n16", "n32")


def read(path: Path, split: str) -> dict[tuple[str, str], dict[int, float]]:
    """{(controller, task): {context: return}} of ``split``'s rows."""
    table: dict[tuple[str, str], dict[int, float]] = defaultdict(dict)  # (controller, task)
    with open(path) as handle:
        for row in csv.DictReader(handle):
            if row.get("split", split) == split:
                name = row.get("controller", "identify-and-plan")
                table[(name, row["task"])][int(row["context"])] = float(row["return"])
    return dict(table)


def paired(ours: dict[int, float], theirs: dict[int, float]) -> str:
    contexts = sorted(ours)
    difference = np.array([ours[c] - theirs[c] for c in contexts])
    if not np.any(difference):
        return "0 (the same returns)"
    interval = bootstrap_ci(difference, statistic=np.mean, n_resamples=10_000, rng=0)
    return (f"{interval.estimate:+.3f} [{interval.low:+.3f}, {interval.high:+.3f}] "
            f"({int((difference > 1e-12).sum())} / {int((difference < -1e-12).sum())})")


def main() -> None:
    for split in ("validation", "test"):
        path = DATA / f"{split}.csv"
        if not path.exists():
            continue
        table, named = read(path, split), read(NAMED[split], split)
        print(f"\n{split} sets (100 networks each)\n")
        print("| controller | task | mean return | − the fixed rule [95 %] (better / worse) "
              "| − identify-and-plan [95 %] (better / worse) |")
        print("|---|---|---:|---|---|")
        for (name, task), returns in table.items():
            rule = table[("rule", task)]
            versus_rule = "" if name == "rule" else paired(returns, rule)
            reference = named.get(("identify-and-plan", task))
            versus_named = paired(returns, reference) if reference else "(not played)"
            print(f"| {name} | `{task}` | {np.mean(list(returns.values())):.3f} | "
                  f"{versus_rule} | {versus_named} |")
        for task in TASKS:
            if ("identify-and-plan", task) in named:
                values = list(named[("identify-and-plan", task)].values())
                print(f"| identify-and-plan (named) | `{task}` | {np.mean(values):.3f} | | |")


if __name__ == "__main__":
    main()
