"""Draw the figure and tables of docs/baselines.md from the committed per-context CSVs.

    python lab/results/baselines/plot_baselines.py docs/results/baselines \
        docs/images/baselines.png

Reads ``curve_noise{sigma}_hidden{fraction}.csv`` (measurement noise x hidden
fraction, n = 8), ``test_n32.csv`` and the main job's TDRQN (three seeds trained on
the suite's ``paper`` task) played on the suite's tasks of the same noise and hidden
fraction (``../suite/trained/guided-upr24/paper/seed=*/transfer.csv``). Writes the
figure and ``summary.md`` (the tables) beside the CSVs. Nothing is recomputed: only
saved results are read.
"""

import csv
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.figures import subplots

NOISE_MV = (0, 1, 2, 4)
HIDDEN_FRACTIONS = ("0", "0.25")
CONTROLLERS = ("do_nothing", "random", "identify_and_plan", "oracle", "witness")
LABELS = {
    "do_nothing": "do nothing",
    "random": "random",
    "identify_and_plan": "identify-and-plan",
    "oracle": "oracle planner",
    "witness": "witness",
}


def read_returns(path: Path) -> dict[str, np.ndarray]:
    """controller -> per-context returns [S] of one CSV."""
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    return {
        name: np.array([float(row[name]) for row in rows]) for name in rows[0] if name != "context"
    }


def cell(values: np.ndarray, spread: bool) -> str:
    if not spread:
        return f"{values.mean():.3f}"
    return f"{values.mean():.3f} ± {values.std(ddof=1):.3f}"


def summary_table(results: Path) -> str:
    header = "| setting | " + " | ".join(LABELS[name] for name in CONTROLLERS) + " |"
    lines = [header, "|---" * (len(CONTROLLERS) + 1) + "|"]
    settings = [
        (f"n = 8, noise {sigma} mV, hidden {fraction}",
         results / f"curve_noise{sigma}_hidden{fraction}.csv")
        for fraction in HIDDEN_FRACTIONS for sigma in NOISE_MV
    ] + [("n = 32", results / "test_n32.csv")]  # fmt: skip
    for label, path in settings:
        if not path.exists():
            continue
        returns = read_returns(path)
        values = [
            cell(returns[name], name in ("identify_and_plan", "oracle")) if name in returns else "–"
            for name in CONTROLLERS
        ]
        lines.append(f"| {label} | " + " | ".join(values) + " |")
    return "\n".join(lines)


TDRQN_TASKS = {("0", 0): "paper", ("0", 1): "noise1", ("0", 2): "noise2", ("0", 4): "noise4",
               ("0.25", 0): "hidden25"}
"""(hidden fraction, noise sigma) -> the benchmark suite's task with that setting."""


def tdrqn_returns(results: Path, fraction: str) -> tuple[list[int], list[float], list[float]]:
    """The main job's TDRQN (the guided preset trained on the suite's ``paper`` task,
    seeds 0-2, best on validation) played on the suite's task of each noise level at
    this hidden fraction: sigmas, mean and sd over the seeds of the test return (from
    the seeds' committed transfer.csv; the suite's test sets, not the curve's)."""
    folder = results.resolve().parent / "suite" / "trained" / "guided-upr24" / "paper"
    by_task: dict[str, list[float]] = {}
    for path in sorted(folder.glob("seed=*/transfer.csv")):
        with path.open() as handle:
            for row in csv.DictReader(handle):
                by_task.setdefault(row["task"], []).append(float(row["mean_return"]))
    sigmas, means, sds = [], [], []
    for (hidden, sigma), task in TDRQN_TASKS.items():
        if hidden == fraction and len(by_task.get(task, [])) > 1:
            sigmas.append(sigma)
            means.append(float(np.mean(by_task[task])))
            sds.append(float(np.std(by_task[task], ddof=1)))
    return sigmas, means, sds


def plot(results: Path, out: Path) -> None:
    figure, axes = subplots(1, 2, figsize=(9, 3.6), sharey=True)
    for axis, fraction in zip(axes, HIDDEN_FRACTIONS, strict=True):
        paths = [results / f"curve_noise{sigma}_hidden{fraction}.csv" for sigma in NOISE_MV]
        present = [(sigma, path) for sigma, path in zip(NOISE_MV, paths, strict=True)
                   if path.exists()]  # fmt: skip
        if not present:
            continue
        curves = [read_returns(path) for _, path in present]
        sigmas = [sigma for sigma, _ in present]
        for name in CONTROLLERS:
            if not all(name in curve for curve in curves):
                continue
            means = [curve[name].mean() for curve in curves]
            errors = [curve[name].std(ddof=1) / np.sqrt(curve[name].size) for curve in curves]
            axis.errorbar(sigmas, means, yerr=errors, marker="o", capsize=2, label=LABELS[name])
        sigmas, means, sds = tdrqn_returns(results, fraction)
        if sigmas:
            axis.errorbar(sigmas, means, yerr=sds, marker="s", color="black",
                          linestyle="none", capsize=3,
                          label="TDRQN, the main job (3 seeds)")  # fmt: skip
        axis.set_title(f"n = 8, hidden fraction {fraction}")
        axis.set_xlabel("measurement noise sigma (mV)")
        axis.set_xticks(list(NOISE_MV))
        axis.axhline(0.5, color="grey", linewidth=0.5)
    axes[0].set_ylabel("mean return, 100 unseen networks")
    axes[0].set_ylim(0.4, 1.03)
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, ncol=3, fontsize=8, loc="upper center")
    figure.tight_layout(rect=(0, 0, 1, 0.84))
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, format="png", dpi=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    results_dir, figure_path = Path(sys.argv[1]), Path(sys.argv[2])
    table = summary_table(results_dir)
    (results_dir / "summary.md").write_text(
        "Mean return over 100 unseen test networks (± sd over networks), from the CSVs "
        "beside this file\n(written by plot_baselines.py).\n\n" + table + "\n",
    )
    print(table)
    plot(results_dir, figure_path)
