"""The learned rows of docs/research/benchmark-suite.md (docs/benchmark.md quotes them),
from the committed results of train.sh:

    python lab/results/suite/learned_table.py

For every task with trained seeds (trained/PRESET/TASK/seed=S/benchmark.csv, the run's
best_model.pt chosen on the task's validation set and scored on its test set): the mean
test return ± sd over seeds (ddof 0), its IQM over seeds with the 95% bootstrap interval,
the normalised score, identify-and-plan on the same test set (identify-and-plan.csv), the
difference, and core-minutes of training (metrics.csv's last cpu_time_s, one Torch
thread). Reads saved results only.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import bootstrap_ci, iqm

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite"
TASKS = ("paper", "n16", "n32", "noise1", "noise2", "noise4", "hidden25", "stochastic",
         "heterogeneous", "background")  # fmt: skip


TRANSFER_PRESETS = {
    "quick": "`quick`",
    "guided": "`guided`, floor 0.2",
    "guided-conn": "`guided` + connectivity loss",
    "guided-upr24": "`guided`, 24 updates a round (the main job)",
}
"""The folders of trained/ whose seeds, trained on `paper`, were played on every task
(transfer.csv) → their label: the quick preset, the guided preset before the connectivity
loss (runs of docs/results/guided-floor20), with it (guided-conn01) and with it and 24
updates a round instead of 32 (guided-upr24, the main job since the fourth stop of
2026-11-24)."""


ON_TASK_PRESETS = {"quick": "`quick`", "guided-upr24": "`guided` (the main job)"}
"""The folders of trained/ with seeds trained on a task itself (benchmark.csv) → label."""


def read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as file:
        return list(csv.DictReader(file))


def by_task(path: Path) -> dict[str, dict[str, str]]:
    return {row["task"]: row for row in read_rows(path)}


def core_minutes(metrics: Path) -> float:
    return float(read_rows(metrics)[-1]["cpu_time_s"]) / 60


def seeds_of(preset: str, task: str) -> list[Path]:
    return sorted((HERE / "trained" / preset / task).glob("seed=*/benchmark.csv"))


def transfer_rows(preset: str) -> dict[str, np.ndarray]:
    """task -> the test returns on it of the seeds of ``preset`` trained on ``paper``
    (their transfer.csv)."""
    files = sorted((HERE / "trained" / preset / "paper").glob("seed=*/transfer.csv"))
    tables = [by_task(path) for path in files]
    return {task: np.array([float(t[task]["mean_return"]) for t in tables]) for task in TASKS}


def print_leaderboard() -> None:
    """Mean normalised score over the ten tasks: training-free controllers from their
    CSVs, the trained ones per seed (from transfer.csv), mean ± sd over seeds."""
    print("| controller | training (core-minutes per seed) | mean normalised score, 10 tasks |")
    print("|---|---|---:|")
    for name, label in (("oracle", "oracle planner (knows the network)"),
                        ("identify-and-plan", "identify-and-plan"),
                        ("random", "random (10 seeds)"), ("do-nothing", "do nothing")):  # fmt: skip
        table = by_task(HERE / f"{name}.csv")
        score = np.mean([float(table[task]["normalised"]) for task in TASKS])
        print(f"| {label} | none | {score:.3f} |")
    for preset in reversed(list(TRANSFER_PRESETS)):
        files = sorted((HERE / "trained" / preset / "paper").glob("seed=*/transfer.csv"))
        scores = [np.mean([float(by_task(path)[task]["normalised"]) for task in TASKS])
                  for path in files]  # fmt: skip
        minutes = np.mean([core_minutes(path.parent / "metrics.csv") for path in files])
        print(
            f"| TDRQN {TRANSFER_PRESETS[preset]}, trained on `paper` ({len(files)} seeds) "
            f"| {minutes:.1f} | "
            f"{np.mean(scores):.3f} ± {np.std(scores):.3f} |"
        )
    print_specialists("guided-upr24", ON_TASK_PRESETS["guided-upr24"])


def print_specialists(preset: str, label: str) -> None:
    """The leaderboard row of ``preset`` as a specialist: seed S trained on each task
    where every seed of its `paper` runs has a counterpart (seed S of that task), and its
    `paper` seed S played zero-shot on the other tasks (a task with fewer seeds, a pilot,
    counts as not trained on)."""

    def on_task(task: str, seed: str) -> Path:
        return HERE / "trained" / preset / task / seed / "benchmark.csv"

    transfer_files = sorted((HERE / "trained" / preset / "paper").glob("seed=*/transfer.csv"))
    seeds = [path.parent.name for path in transfer_files]
    trained_tasks = [task for task in TASKS if task != "paper"
                     and all(on_task(task, seed).exists() for seed in seeds)]  # fmt: skip
    scores, minutes = [], []
    for path, seed in zip(transfer_files, seeds, strict=True):
        own = {task: on_task(task, seed) for task in trained_tasks}
        table = by_task(path)  # `paper` and the zero-shot tasks
        table.update({task: by_task(file)[task] for task, file in own.items()})
        scores.append(np.mean([float(table[task]["normalised"]) for task in TASKS]))
        minutes += [core_minutes(file.parent / "metrics.csv") for file in [path, *own.values()]]
    zero_shot = [task for task in TASKS if task != "paper" and task not in trained_tasks]
    trained_on, detail = "each task", f"{len(scores)} seeds"
    if zero_shot:
        trained_on += f" but {', '.join(f'`{t}`' for t in zero_shot)}"
        detail = f"played from `paper`; {detail}"
    runs = len(trained_tasks) + 1
    print(
        f"| TDRQN {label}, trained on {trained_on} ({detail}) "
        f"| {np.sum(minutes) / len(scores):.0f} in all, {runs} runs of "
        f"{np.min(minutes):.1f}–{np.max(minutes):.1f} | "
        f"{np.mean(scores):.3f} ± {np.std(scores):.3f} |"
    )


def main() -> None:
    planner = by_task(HERE / "identify-and-plan.csv")
    transfer = {preset: transfer_rows(preset) for preset in TRANSFER_PRESETS}
    print("| task | identify-and-plan | "
          + " | ".join(f"TDRQN {label} | − planner" for label in TRANSFER_PRESETS.values())
          + " |")  # fmt: skip
    print("|---|---:|" + "---:|---:|" * len(TRANSFER_PRESETS))
    for task in TASKS:
        reference = float(planner[task]["mean_return"])
        cells = []
        for returns in (transfer[preset][task] for preset in TRANSFER_PRESETS):
            cells += [f"{returns.mean():.3f} ± {returns.std():.3f}",
                      f"{returns.mean() - reference:+.3f}"]  # fmt: skip
        print(f"| `{task}` | {reference:.3f} | " + " | ".join(cells) + " |")
    print()
    print_leaderboard()
    print()
    print(
        "| task | identify-and-plan | learner | trained on the task (seeds) | IQM [95% CI] "
        "| normalised | learned − planner | core-minutes |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|")
    for task in TASKS:
        for preset, label in ON_TASK_PRESETS.items():
            files = seeds_of(preset, task)
            if not files:
                continue
            rows = [by_task(path)[task] for path in files]
            returns = np.array([float(row["mean_return"]) for row in rows])
            normalised = np.array([float(row["normalised"]) for row in rows])
            minutes = [core_minutes(path.parent / "metrics.csv") for path in files]
            _, low, high = bootstrap_ci(returns, iqm)
            reference = float(planner[task]["mean_return"])
            print(f"| `{task}` | {reference:.3f} | {label} "
                  f"| {returns.mean():.3f} ± {returns.std():.3f} ({len(files)}) "
                  f"| {iqm(returns):.3f} [{low:.3f}, {high:.3f}] "
                  f"| {normalised.mean():.3f} ± {normalised.std():.3f} "
                  f"| {returns.mean() - reference:+.3f} | {np.mean(minutes):.1f} |")  # fmt: skip

if __name__ == "__main__":
    main()
