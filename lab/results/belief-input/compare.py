"""Two groups of `spikectl benchmark --out X.csv --per-network X-per-network.csv` runs of
the same split (e.g. three seeds with and without an option), task by task: each
group's mean return and normalised score over its runs (± sd over runs), and the
network-by-network difference (new - old) of the runs' mean per network with a 95%
bootstrap interval over the networks (10 000 resamples, seed 0) and how many networks
each way (``spikectl.experiments.stats.paired_difference_cells``). A reference
controller's run may be given with --reference (one column).

    python lab/results/belief-input/compare.py --old A.csv B.csv --new C.csv D.csv \
        [--reference R.csv] [--names old new reference]
"""

from __future__ import annotations

import argparse
import csv

import numpy as np

from spikectl.experiments.stats import paired_difference_cells


def summary(path: str) -> dict[str, dict[str, float]]:
    """task -> {mean_return, normalised, do_nothing, oracle} of one --out CSV."""
    with open(path, newline="") as handle:
        return {
            row["task"]: {
                key: float(row[key])
                for key in ("mean_return", "normalised", "do_nothing", "oracle")
            }  # fmt: skip
            for row in csv.DictReader(handle)
        }


def per_network(path: str) -> dict[str, np.ndarray]:
    """task -> returns [networks] in context order, from the run's per-network CSV."""
    table: dict[str, dict[int, float]] = {}
    with open(path.removesuffix(".csv") + "-per-network.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            table.setdefault(row["task"], {})[int(row["context"])] = float(row["return"])
    return {
        task: np.array([value for _, value in sorted(values.items())])
        for task, values in table.items()
    }


def cell(values: list[float]) -> str:
    values_ = np.array(values)
    if values_.size == 1:
        return f"{values_[0]:.3f}"
    return f"{values_.mean():.3f} ± {values_.std(ddof=1):.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", nargs="+", required=True)
    parser.add_argument("--new", nargs="+", required=True)
    parser.add_argument("--reference", default=None)
    parser.add_argument("--names", nargs="+", default=["old", "new", "reference"])
    args = parser.parse_args()
    old = [(summary(p), per_network(p)) for p in args.old]
    new = [(summary(p), per_network(p)) for p in args.new]
    reference = None if args.reference is None else (
        summary(args.reference), per_network(args.reference))  # fmt: skip
    name_old, name_new, name_ref = (args.names + ["old", "new", "reference"][len(args.names) :])[:3]
    header = [
        "task", f"{name_old} (norm.)", f"{name_new} (norm.)",
        f"{name_new} − {name_old}, network by network", "networks better / worse",
    ]  # fmt: skip
    if reference is not None:
        header += [f"{name_ref} (norm.)", f"{name_new} − {name_ref}", "better / worse"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" + "---:|" * (len(header) - 1))
    tasks = [task for task in old[0][0] if all(task in run[0] for run in old + new)]
    means: dict[str, list[float]] = {"old": [], "new": [], "ref": []}
    for task in tasks:
        cells = [task]
        for group, key in ((old, "old"), (new, "new")):
            raw = [run[0][task]["mean_return"] for run in group]
            norm = [run[0][task]["normalised"] for run in group]
            cells.append(f"{cell(raw)} ({cell(norm)})")
            means[key].append(float(np.mean(norm)))
        old_networks = np.mean([run[1][task] for run in old], axis=0)  # [networks]
        new_networks = np.mean([run[1][task] for run in new], axis=0)
        cells.append(paired_difference_cells(new_networks - old_networks))
        if reference is not None:
            ref = reference[0][task]
            cells.append(f"{ref['mean_return']:.3f} ({ref['normalised']:.3f})")
            cells.append(paired_difference_cells(new_networks - reference[1][task]))
            means["ref"].append(ref["normalised"])
        print("| " + " | ".join(cells) + " |")
    line = f"| mean normalised | {np.mean(means['old']):.3f} | {np.mean(means['new']):.3f} | | |"
    if reference is not None:
        line += f" {np.mean(means['ref']):.3f} | | |"
    print(line)


if __name__ == "__main__":
    main()
