"""The learned rows of suite v2 against identify-and-plan, network by network.

    python lab/results/suite-v2/learned_table.py [FOLDER ...]   # default: guided-in-flight
    python lab/results/suite-v2/learned_table.py --paired FOLDER_A FOLDER_B

For each FOLDER under docs/results/suite-v2/trained/ and each task it holds, the seeds'
test returns (their per_network.csv, written by train.sh) against identify-and-plan's on
the same 1 000 networks (identify-and-plan-per-network.csv): mean ± sd over the seeds,
the seeds' mean minus the planner's per network with its 95% bootstrap interval over
the networks (10 000 resamples, seed 0), and how many networks each way. ``--paired``
sets two folders against each other the same way on every task both hold (each the mean
over its seeds).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite-v2"
PLANNER = HERE / "identify-and-plan-per-network.csv"


def per_network(path: Path, task: str) -> np.ndarray:
    """[networks] test returns on ``task``, in network order."""
    with open(path, newline="") as file:
        rows = [row for row in csv.DictReader(file) if row["task"] == task]
    rows.sort(key=lambda row: int(row["context"]))
    if [int(row["context"]) for row in rows] != list(range(len(rows))) or not rows:
        raise ValueError(f"{path} lacks the test networks of {task}")
    return np.array([float(row["return"]) for row in rows])


def seed_returns(folder: str, task: str) -> np.ndarray | None:
    """[seeds, networks] each seed's test return on each network (None: no seed)."""
    seeds = sorted((HERE / "trained" / folder / task).glob("seed=*/per_network.csv"))
    return np.stack([per_network(path, task) for path in seeds]) if seeds else None


def table(folder: str) -> str:
    lines = [
        f"Preset folder `{folder}`, suite v2 test sets; mean ± sd over seeds.",
        "",
        "| task | seeds | learned | identify-and-plan | learned − planner, per network [95%] "
        "| better / worse |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for task_dir in sorted((HERE / "trained" / folder).iterdir()):
        task = task_dir.name
        returns = seed_returns(folder, task)  # [seeds, networks]
        if returns is None:
            continue
        means = returns.mean(axis=1)
        planner = per_network(PLANNER, task)
        cells = paired_difference_cells(returns.mean(axis=0) - planner)
        lines.append(
            f"| `{task}` | {len(returns)} | {means.mean():.3f} ± {means.std():.3f} "
            f"| {planner.mean():.3f} | {cells} |"
        )
    return "\n".join(lines)


def paired(first: str, second: str) -> str:
    lines = [
        f"| task | `{first}` | `{second}` | `{first}` − `{second}`, per network [95%] "
        "| better / worse |",
        "|---|---:|---:|---:|---:|",
    ]
    shared = sorted(
        task.name
        for task in (HERE / "trained" / first).iterdir()
        if (HERE / "trained" / second / task.name).is_dir()
    )
    for task in shared:
        a, b = seed_returns(first, task), seed_returns(second, task)  # [seeds, networks]
        lines.append(
            f"| `{task}` | {a.mean():.3f} ({len(a)} seeds) | {b.mean():.3f} ({len(b)} seeds) "
            f"| {paired_difference_cells(a.mean(axis=0) - b.mean(axis=0))} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="*", default=["guided-in-flight"])
    parser.add_argument(
        "--paired",
        nargs=2,
        metavar=("FOLDER_A", "FOLDER_B"),
        help="the two folders against each other, network by network",
    )
    arguments = parser.parse_args()
    if arguments.paired:
        print(paired(*arguments.paired))
        return
    for folder in arguments.folders:
        print(table(folder))
        print()


if __name__ == "__main__":
    main()
