"""Draw docs/images/suite_realism.png from the saved CSVs of this folder (run.sh wrote them):
the normalised score and the raw return of each training-free controller against measurement
noise (tasks paper, noise1, noise2, noise4) and against the hidden fraction (paper,
hidden25). Reads only saved results; run from the repository root:

    python docs/results/suite/plot_suite.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

HERE = Path(__file__).resolve().parent
OUT = HERE.parents[2] / "docs" / "images" / "suite_realism.png"
CONTROLLERS = {"oracle": "oracle planner", "identify-and-plan": "identify-and-plan",
               "random": "random (10 seeds)", "do-nothing": "do nothing"}  # fmt: skip
NOISE = {"paper": 0.0, "noise1": 1.0, "noise2": 2.0, "noise4": 4.0}
HIDDEN = {"paper": 0.0, "hidden25": 0.25}


def rows(controller: str) -> dict[str, dict[str, str]]:
    with open(HERE / f"{controller}.csv", newline="") as file:
        return {row["task"]: row for row in csv.DictReader(file)}


def main() -> None:
    figure, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharey=True)
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
    axes[0].legend(fontsize=8, loc="lower right", bbox_to_anchor=(1.0, 0.1))
    figure.tight_layout()
    figure.savefig(OUT, dpi=120)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
