"""Draw docs/images/suite_realism.png from the saved CSVs of this folder (run.sh and train.sh
wrote them): the raw return of each training-free controller, of the quick and guided
TDRQNs trained on `paper` (transfer; mean and sd over their seeds) and of the quick TDRQN
and the main job trained on the task itself (where trained) against measurement noise (tasks paper,
noise1, noise2, noise4) and against the hidden fraction (paper, hidden25). Reads only
saved results; run from the repository root:

    python lab/results/suite/plot_suite.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite"
OUT = HERE.parents[2] / "docs" / "images" / "suite_realism.png"
CONTROLLERS = {"oracle": "oracle planner", "identify-and-plan": "identify-and-plan",
               "random": "random (10 seeds)", "do-nothing": "do nothing"}  # fmt: skip
NOISE = {"paper": 0.0, "noise1": 1.0, "noise2": 2.0, "noise4": 4.0}
HIDDEN = {"paper": 0.0, "hidden25": 0.25}


def rows(controller: str) -> dict[str, dict[str, str]]:
    with open(HERE / f"{controller}.csv", newline="") as file:
        return {row["task"]: row for row in csv.DictReader(file)}


def seed_returns(pattern: str, tasks: dict[str, float]) -> tuple[list, np.ndarray]:
    """(x of each task with results, [tasks, 2] mean and sd over seeds) from the trained/
    CSVs; ``pattern`` is a glob under trained/ with {task} in it, or several joined by |."""
    xs, returns = [], []
    for task, x in tasks.items():
        files = sorted(path for part in pattern.split("|")
                       for path in (HERE / "trained").glob(part.format(task=task)))  # fmt: skip
        values = [float(row["mean_return"]) for path in files for row in
                  csv.DictReader(open(path, newline="")) if row["task"] == task]  # fmt: skip
        if values:
            xs.append(x)
            returns.append((np.mean(values), np.std(values)))
    return xs, np.array(returns).reshape(-1, 2)


def main() -> None:
    figure, axes = plt.subplots(1, 2, figsize=(9, 4.2), sharey=True)
    for pattern, label, style, colour in (
        ("quick/paper/seed=*/transfer.csv", "TDRQN quick, trained on paper", "s--", "tab:purple"),
        ("quick/{task}/seed=*/benchmark.csv", "TDRQN quick, trained on the task", "D-",
         "tab:brown"),
        ("guided/paper/seed=*/transfer.csv", "TDRQN guided, floor 0.2, trained on paper", "^-",
         "tab:pink"),
        ("guided-conn/paper/seed=*/transfer.csv",
         "TDRQN guided + connectivity loss, 32 updates, trained on paper", "v-", "tab:olive"),
        ("guided-upr24/paper/seed=*/transfer.csv",
         "TDRQN guided, 24 updates (main job), trained on paper", "P-", "tab:cyan"),
        # Markers only: the main job is trained on some of the tasks (paper's point is
        # its transfer.csv, the others' their benchmark.csv).
        ("guided-upr24/{task}/seed=*/benchmark.csv|guided-upr24/{task}/seed=*/transfer.csv",
         "TDRQN guided (main job), trained on the task",
         "X", "black"),
    ):
        for index, (axis, tasks) in enumerate(zip(axes, (NOISE, HIDDEN), strict=True)):
            xs, stats = seed_returns(pattern, tasks)
            if xs:
                axis.errorbar(xs, stats[:, 0], yerr=stats[:, 1], fmt=style, capsize=3,
                              color=colour,
                              label=label if index == 0 else None)  # fmt: skip
    for controller, label in CONTROLLERS.items():
        table = rows(controller)
        for axis, tasks in zip(axes, (NOISE, HIDDEN), strict=True):
            xs = list(tasks.values())
            ys = [float(table[task]["mean_return"]) for task in tasks]
            axis.plot(xs, ys, marker="o", label=label)
    axes[0].set_xlabel("measurement noise sigma (mV)")
    axes[1].set_xlabel("fraction of hidden neurons")
    axes[0].set_ylabel("mean return, suite v1 test set (n = 8)")
    axes[1].set_xticks(list(HIDDEN.values()))
    for axis in axes:
        axis.grid(alpha=0.3)
    figure.legend(*axes[0].get_legend_handles_labels(), fontsize=8, loc="lower center",
                  ncol=3, frameon=False)  # fmt: skip
    figure.tight_layout(rect=(0, 0.14, 1, 1))
    figure.savefig(OUT, dpi=120)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
