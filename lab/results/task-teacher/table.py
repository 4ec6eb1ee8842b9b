"""The tables of docs/results/task-teacher/README.md, from committed files only.

    python lab/results/task-teacher/table.py > docs/results/task-teacher/table.md

Per task, the main job trained on it with the teacher playing the task's settings
(trials/TASK/seed=S) against the same runs with the constructor's teacher
(../suite/trained/guided-upr24/TASK/seed=S): the validation return its metrics.csv
records during training (mean over seeds, then each seed), the best evaluation's
validation return, the end's teacher agreement and core-minutes, and the best model's
test return (benchmark.csv). Then each new run's best model on the 100 test networks
against the named identify-and-plan's committed rows (:data:`PLANNER_TEST`), network by
network: the mean difference over networks of the seeds' mean, with a 95% bootstrap
interval over networks (``spikectl.experiments.stats.paired_difference_cells``).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "task-teacher"
RESULTS = HERE.parent
OLD = RESULTS / "suite" / "trained" / "guided-upr24"
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # result_tables
from result_tables import PLANNER_TEST  # noqa: E402  (each task's named identify-and-plan)

TASKS = ("heterogeneous", "n16")
"""The tasks with students of the task's teacher (trials/TASK/seed=S), in the table's order."""


def rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def seeds(folder: Path) -> list[Path]:
    return sorted(folder.glob("seed=*"))


def per_network(path: Path, task: str) -> np.ndarray:
    table = [row for row in rows(path) if row["task"] == task]
    table.sort(key=lambda row: int(row["context"]))
    return np.array([float(row["return"]) for row in table])


def report(task: str) -> None:
    groups = {"the task's settings": HERE / "trials" / task, "the constructor's": OLD / task}
    runs = {label: [rows(seed / "metrics.csv") for seed in seeds(folder)]
            for label, folder in groups.items()}  # fmt: skip
    print(f"## `{task}`\n\nValidation return during training (mean over seeds; each seed)\n")
    print("| episode | teacher: " + " | teacher: ".join(runs) + " |")
    print("|---:|" + "---:|" * len(runs))
    for index, row in enumerate(next(iter(runs.values()))[0]):
        cells = []
        for metrics in runs.values():
            values = [float(seed[index]["val_return"]) for seed in metrics]
            cells.append(f"{np.mean(values):.3f} ({' / '.join(f'{v:.3f}' for v in values)})")
        print(f"| {row['episode']} | " + " | ".join(cells) + " |")
    print("\n| teacher | seeds | validation at the end | best validation | test return of the "
          "best | teacher agreement at the end | core-minutes (teacher) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for label, folder in groups.items():
        metrics = runs[label]
        end = [float(seed[-1]["val_return"]) for seed in metrics]
        best = [max(float(row["val_return"]) for row in seed) for seed in metrics]
        tests = [float(rows(seed / "benchmark.csv")[0]["mean_return"]) for seed in seeds(folder)]
        agreement = [float(seed[-1]["teacher_agreement"]) for seed in metrics]
        minutes = [float(seed[-1]["cpu_time_s"]) / 60 for seed in metrics]
        teacher = [float(seed[-1]["teacher_seconds"]) / 60 for seed in metrics]
        print(f"| {label} | {len(metrics)} | {np.mean(end):.3f} ± {np.std(end):.3f} | "
              f"{np.mean(best):.3f} ± {np.std(best):.3f} | "
              f"{np.mean(tests):.3f} ({' / '.join(f'{t:.3f}' for t in tests)}) | "
              f"{np.mean(agreement):.3f} | "
              f"{np.mean(minutes):.1f} ({np.mean(teacher):.1f}) |")  # fmt: skip
    new = [seed / "per_network.csv" for seed in seeds(groups["the task's settings"])]
    student = np.mean([per_network(path, task) for path in new], axis=0)
    planner = per_network(PLANNER_TEST, task)
    print("\nTest networks, network by network: the new runs' mean against identify-and-plan\n")
    print("| | student − planner | mean difference [95% CI] | better / worse |")
    print("|---|---:|---:|---:|")
    cells = paired_difference_cells(student - planner)
    print(f"| {task} | {student.mean():.3f} − {planner.mean():.3f} | {cells} |\n")


def main() -> None:
    for task in TASKS:
        if seeds(HERE / "trials" / task):
            report(task)


if __name__ == "__main__":
    main()
