"""The reference baselines' table and learning curves, from the committed runs of run.py.

    python lab/results/reference-baselines/table.py [--figure]

Reads docs/results/reference-baselines/TASK/ALGORITHM/seedS/ (result.json,
test-per-network.csv, curve.csv) and prints, per task, one row per algorithm: the test
mean return and normalised score (mean ± sd over seeds), the IQM of the normalised
per-seed scores with its stratified-bootstrap 95% interval, training core-minutes per
seed, and the paired differences network by network (the seeds' mean return on each
test network minus the reference's: mean with its 95% bootstrap interval over the
networks, and how many networks each way) to identify-and-plan
(docs/results/suite/identify-and-plan-per-network.csv) and to the suite's TDRQN
``guided`` trained on the task (the mean of its seeds' per_network.csv under
TASK/tdrqn-guided/ where run here, else those of the suite's committed row). ``--figure`` also draws
``curves.png`` (training return per 20 000 steps, mean over seeds, the seeds' range
shaded).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells, summarise

RESULTS = Path(__file__).resolve().parents[3] / "docs" / "results"
HERE = RESULTS / "reference-baselines"
PLANNER = RESULTS / "suite" / "identify-and-plan-per-network.csv"
SUITE_TDRQN = RESULTS / "suite" / "trained" / "guided-upr24"
ORDER = ("cleanrl-ppo", "cleanrl-dqn", "cleanrl-pqn", "sb3-ppo", "sb3-maskable-ppo", "sb3-dqn",
         "sb3-recurrent-ppo")  # fmt: skip


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def runs(task: str, algorithm: str) -> list[Path]:
    folder = HERE / task / algorithm
    return sorted(path.parent for path in folder.glob("seed*/result.json"))


def planner_returns(task: str) -> np.ndarray:
    rows = [row for row in read_csv(PLANNER) if row["task"] == task and row["split"] == "test"]
    rows.sort(key=lambda row: int(row["context"]))
    return np.array([float(row["return"]) for row in rows])


def tdrqn_files(task: str) -> list[Path]:
    """The TDRQN ``guided`` seeds' per_network.csv: those retrained here, else the ones the
    suite's committed row has (docs/results/suite/trained/guided-upr24/TASK)."""
    files = sorted((HERE / task / "tdrqn-guided").glob("seed*/per_network.csv"))
    return files or sorted((SUITE_TDRQN / task).glob("seed=*/per_network.csv"))


def tdrqn_returns(task: str) -> np.ndarray | None:
    """[networks] the TDRQN ``guided`` seeds' mean test return per network, if run."""
    files = tdrqn_files(task)
    if not files:
        return None
    per_seed = []
    for path in files:
        rows = sorted(read_csv(path), key=lambda row: int(row["context"]))
        per_seed.append([float(row["return"]) for row in rows])
    return np.mean(per_seed, axis=0)


def seed_count(count: int) -> str:
    return f"{count} seed" + ("s" if count != 1 else "")


def row_of(task: str, algorithm: str) -> str | None:
    seeds = runs(task, algorithm)
    if not seeds:
        return None
    results = [json.loads((seed / "result.json").read_text()) for seed in seeds]
    means = np.array([r["test_mean_return"] for r in results])
    normalised = np.array([r["test_normalised"] for r in results])
    per_network = np.array([
        [float(row["return"]) for row in read_csv(seed / "test-per-network.csv")]
        for seed in seeds
    ])  # [seeds, networks]
    summary = summarise(normalised)
    minutes = np.median([r["train_core_minutes"] for r in results])
    played = per_network.mean(axis=0)
    tdrqn = tdrqn_returns(task)
    to_tdrqn = "n/a | n/a" if tdrqn is None else paired_difference_cells(played - tdrqn)
    return (
        f"| {algorithm} | {len(seeds)} | {means.mean():.3f} ± {means.std():.3f} | "
        f"{normalised.mean():.3f} ± {normalised.std():.3f} | {summary['iqm']:.3f} "
        f"[{summary['iqm_low']:.3f}, {summary['iqm_high']:.3f}] | {minutes:.1f} | "
        f"{paired_difference_cells(played - planner_returns(task))} | {to_tdrqn} |"
    )


def table(task: str) -> str:
    lines = [
        f"Task `{task}`, 100 test networks, greedy play; mean ± sd over seeds.",
        "",
        "| algorithm | seeds | test mean return | normalised | IQM normalised [95%] | "
        "core-min a seed | − identify-and-plan, per network [95%] | better / worse | "
        "− TDRQN guided, per network [95%] | better / worse |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    rows = [row_of(task, algorithm) for algorithm in ORDER]
    return "\n".join(lines + [row for row in rows if row])


def suite_normalised(task: str) -> dict[str, float]:
    """The suite's committed normalised test scores on ``task``: identify-and-plan's and
    the TDRQN ``guided`` trained on the task (mean over its seeds)."""
    suite = RESULTS / "suite"
    planner = next(r for r in read_csv(suite / "identify-and-plan.csv")
                   if r["task"] == task and r["split"] == "test")  # fmt: skip
    name = "transfer.csv" if task == "paper" else "benchmark.csv"
    trained = [next(r for r in read_csv(path) if r["task"] == task)
               for path in sorted((SUITE_TDRQN / task).glob(f"seed=*/{name}"))]  # fmt: skip
    return {"identify-and-plan": float(planner["normalised"]),
            "TDRQN guided, trained on the task": float(np.mean([float(r["normalised"])
                                                               for r in trained]))}  # fmt: skip


def leaderboard(tasks: list[str]) -> str:
    """The generic baselines beside the suite's controllers on the tasks they ran: the
    normalised test score per task (mean over seeds) and its mean over the tasks."""
    header = "| controller | " + " | ".join(f"`{task}`" for task in tasks) + " | mean |"
    lines = [header, "|---|" + "---:|" * (len(tasks) + 1)]
    scores: dict[str, dict[str, float]] = {}
    for task in tasks:
        for name, value in suite_normalised(task).items():
            scores.setdefault(name, {})[task] = value
        for algorithm in ORDER:
            seeds = runs(task, algorithm)
            if len(seeds) == 3:
                values = [json.loads((seed / "result.json").read_text())["test_normalised"]
                          for seed in seeds]  # fmt: skip
                scores.setdefault(f"{algorithm} (generic baseline)", {})[task] = np.mean(values)
    for name, by_task in scores.items():
        if len(by_task) == len(tasks):
            cells = " | ".join(f"{by_task[task]:.3f}" for task in tasks)
            lines.append(f"| {name} | {cells} | {np.mean(list(by_task.values())):.3f} |")
    lines.append("| do nothing | " + " | ".join("0.000" for _ in tasks) + " | 0.000 |")
    return "\n".join(lines)


def figure(tasks: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(tasks), figsize=(5.5 * len(tasks), 4), squeeze=False)
    for axis, task in zip(axes[0], tasks, strict=True):
        for algorithm in ORDER:
            seeds = runs(task, algorithm)
            if not seeds:
                continue
            curves = [read_csv(seed / "curve.csv") for seed in seeds]
            steps = np.array([int(row["step"]) for row in curves[0]])
            values = np.array([
                [float(row["mean_return"]) if row["mean_return"] else np.nan for row in curve]
                for curve in curves
            ])  # [seeds, bins]
            colour = f"C{ORDER.index(algorithm)}"  # the same in every panel
            axis.plot(steps, np.nanmean(values, axis=0), color=colour,
                      label=f"{algorithm} ({len(seeds)})")  # fmt: skip
            axis.fill_between(steps, np.nanmin(values, 0), np.nanmax(values, 0), color=colour,
                              alpha=0.2)  # fmt: skip
        axis.axhline(0.5, color="grey", linestyle=":", label="do nothing")
        axis.set(title=f"{task}: training return", xlabel="environment steps",
                 ylabel="mean episode return (training networks)")  # fmt: skip
        axis.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "curves.png", dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", action="store_true")
    args = parser.parse_args()
    tasks = sorted(path.name for path in HERE.iterdir() if path.is_dir())
    print("\n\n".join(table(task) for task in tasks))
    print("\nNormalised test score, the generic baselines with 3 seeds on every task:\n")
    print(leaderboard(tasks))
    for task in tasks:
        tdrqn = tdrqn_returns(task)
        if tdrqn is not None:
            where = tdrqn_files(task)[0].parents[1].relative_to(RESULTS)
            print(f"\n{task}: TDRQN guided (the reference), mean test return {tdrqn.mean():.3f} "
                  f"({seed_count(len(tdrqn_files(task)))}, docs/results/{where})")  # fmt: skip
    if args.figure:
        figure(tasks)


if __name__ == "__main__":
    main()
