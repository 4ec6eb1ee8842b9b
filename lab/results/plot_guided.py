"""Learning curves against core-minutes: the quick preset and the guided learners
(the rows of guided_table.py), from committed results only.

    python lab/results/plot_guided.py docs/results docs/images/guided_core_minutes.png

Each curve is the mean over seeds of the greedy return on the validation networks
(left) and the unseen test networks (right) against the process CPU time of the run
(teacher included), each seed interpolated onto a common grid within the range all
seeds reach; the shade is ± one standard deviation over seeds. Identify-and-plan's
return (no training) is the dashed line.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from guided_table import GROUPS, runs_of  # lab/results/guided_table.py, beside this script
from matplotlib import colormaps

from spikectl.experiments.figures import save_figure, subplots
from spikectl.training.run_files import read_metrics

IDENTIFY_AND_PLAN = {"val_return": 0.866, "test_return": 0.837}  # docs/baselines.md
MAIN_JOB = "guided-ntrain1000"
"""The folder of the README's main job, drawn thicker."""


def curve(run_dirs: list[Path], column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(core-minutes grid, mean, sd) of ``column`` over the runs."""
    series = []
    for run_dir in run_dirs:
        rows = read_metrics(run_dir)
        minutes = np.array([row["cpu_time_s"] for row in rows]) / 60.0
        series.append((minutes, np.array([row[column] for row in rows])))
    end = min(minutes[-1] for minutes, _ in series)
    grid = np.linspace(0.0, end, 60)
    values = np.stack([np.interp(grid, minutes, value) for minutes, value in series])
    return grid, values.mean(axis=0), values.std(axis=0)


def main(results: Path, out: Path) -> None:
    figure, axes = subplots(1, 2, figsize=(11.0, 8.0), sharey=True)
    panels = (("val_return", "validation networks"), ("test_return", "unseen test networks"))
    for axis, (column, title) in zip(axes, panels, strict=True):
        for index, (label, folder) in enumerate(GROUPS.items()):
            runs = runs_of(results, folder)
            if not runs:
                continue
            grid, mean, sd = curve(runs, column)
            # tab20 keeps 20 groups apart (the default cycle repeats after 10), tab20b 20 more.
            color = colormaps["tab20"](index) if index < 20 else colormaps["tab20b"](index - 20)
            width = 2.5 if folder == MAIN_JOB else 1.2
            seeds = f"{len(runs)} seed{'s' if len(runs) > 1 else ''}"
            label = label.replace("`", "")
            axis.plot(grid, mean, color=color, linewidth=width, label=f"{label} ({seeds})")
            axis.fill_between(grid, mean - sd, mean + sd, color=color, alpha=0.2)
        axis.axhline(IDENTIFY_AND_PLAN[column], color="k", linestyle="--", linewidth=1,
                     label="identify-and-plan (no training)")  # fmt: skip
        axis.axhline(0.5, color="grey", linestyle=":", linewidth=1)
        axis.set_title(title)
        axis.set_xlabel("core-minutes (process CPU time, teacher included)")
    axes[0].set_ylabel("greedy return (n = 8)")
    figure.legend(*axes[1].get_legend_handles_labels(), loc="lower center", ncol=2, fontsize=7,
                  frameon=False)  # fmt: skip
    figure.tight_layout(rect=(0, 0.33, 1, 1))
    save_figure(figure, out)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
