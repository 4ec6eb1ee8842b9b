"""Learning curves against core-minutes: the quick preset and the guided learners
(docs/training.md, "Learners that beat the planner"), from committed results only.

    python docs/results/plot_guided.py docs/results docs/images/guided_core_minutes.png

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
from matplotlib import colormaps

from guided_table import runs_of  # docs/results/guided_table.py, beside this script

from spikectl.experiments.figures import save_figure, subplots
from spikectl.training.run_files import read_metrics

IDENTIFY_AND_PLAN = {"val_return": 0.866, "test_return": 0.837}  # docs/baselines.md
GROUPS = {
    "TDRQN, quick preset (committed, another CPU kind)": "learn-fast-pooled-decay",
    "TDRQN, quick preset": "quick-this-machine",
    "guided, weaned to 0 (teacher before compilation)": "guided-identify",
    "guided, teacher told the weights (pilot)": "guided-told-weights-pilot",
    "guided, teacher plays 50% -> 0": "guided-mix50",
    "guided, imitation floor 0.2": "guided-floor20",
    "guided, floor 0.2 + teacher plays 50% -> 0": "guided-floor20-mix50",
    "guided, imitation floor 0.5": "guided-floor50",
    "guided, floor 0.2 + teacher plays 50% -> 0, 4x steps": "guided-floor20-mix50-4x",
    "guided + connectivity loss 0.1, 32 updates a round": "guided-conn01",
    "guided + connectivity loss 1": "guided-conn1",
    "guided + connectivity loss 0.1, 4x steps": "guided-conn01-4x",
    "guided + connectivity loss, 24 updates a round (100 networks)": "guided-upr24",
    "the main job + the others' spikes in the input (AVX-512 host)": "guided-others",
    "guided, 24 a round, on 1 000 networks (the main job; AVX-512 host)": "guided-ntrain1000",
    "the main job on 4 000 training networks, 4x steps (AVX-512 host)": "guided-ntrain4000-4x",
    "the main job with a 128-wide LSTM (AVX-512 host)": "guided-lstm128",
    "PQN": "pqn",
    "the main job + the target's proximity in the input": "proximity-input:trials/n8/seed=*",
    "the main job + its teacher's belief in the input": "belief-input:trials/n8-seed*",
    "the main job + the planner's next action in the input": "advice-input:trials/n8-seed*",
    "the same, imitation annealed to 0 (reward alone)": "advice-input:trials/n8-rl-seed*",
    "ADVISOR, alpha 4 (pilot)": "advisor:trials/identify-a4-end1-seed*",
    "ADVISOR's control: policy head, imitation held at 1 (pilot)":
        "advisor:trials/identify-a0-end1-seed*",
}
"""Legend label -> results folder, or ``folder:glob`` (:func:`guided_table.runs_of`)."""

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
    figure, axes = subplots(1, 2, figsize=(11.0, 5.6), sharey=True)
    panels = (("val_return", "validation networks"), ("test_return", "unseen test networks"))
    for axis, (column, title) in zip(axes, panels, strict=True):
        for index, (label, folder) in enumerate(GROUPS.items()):
            runs = runs_of(results, folder)
            if not runs:
                continue
            grid, mean, sd = curve(runs, column)
            # tab20 keeps 20 groups apart (the default cycle repeats after 10), Dark2 8 more.
            color = colormaps["tab20"](index) if index < 20 else colormaps["Dark2"](index - 20)
            width = 2.5 if folder == MAIN_JOB else 1.2
            seeds = f"{len(runs)} seed{'s' if len(runs) > 1 else ''}"
            axis.plot(grid, mean, color=color, linewidth=width, label=f"{label} ({seeds})")
            axis.fill_between(grid, mean - sd, mean + sd, color=color, alpha=0.2)
        axis.axhline(IDENTIFY_AND_PLAN[column], color="k", linestyle="--", linewidth=1,
                     label="identify-and-plan (no training)")  # fmt: skip
        axis.axhline(0.5, color="grey", linestyle=":", linewidth=1)
        axis.set_title(title)
        axis.set_xlabel("core-minutes (process CPU time, teacher included)")
    axes[0].set_ylabel("greedy return (n = 8)")
    figure.legend(*axes[1].get_legend_handles_labels(), loc="lower center", ncol=3, fontsize=7,
                  frameon=False)  # fmt: skip
    figure.tight_layout(rect=(0, 0.2, 1, 1))
    save_figure(figure, out)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
