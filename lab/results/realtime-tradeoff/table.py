"""Return against decision time at n = 8, 16, 32 and 64, from committed results: the
table (markdown, printed) and ``tradeoff.png`` (``--figure``).

    python lab/results/realtime-tradeoff/table.py [--figure]

Per size: the suite v1 test set's rows (``docs/results/suite``: doing nothing, random,
the oracle, the named identify-and-plan; the main job's TDRQN, trained on ``paper``,
mean over its 3 seeds, from ``trained/guided-upr24/paper/seed=*/transfer.csv``), the
amortised controller (``docs/results/amortised-controller``: test.csv, and the CPU
times of timing.csv), and this folder's ``measure.py`` rows: identify-and-plan's fast
form (fast.csv), the n = 64 set (n64.csv) and the compiled TDRQN's decision times
(compiled-times.csv: the network the TDRQN row plays, compiled, as the rig runs it).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

RESULTS = Path(__file__).resolve().parents[3] / "docs" / "results"
HERE = RESULTS / "realtime-tradeoff"
SUITE = RESULTS / "suite"
AMORTISED = RESULTS / "amortised-controller"
TDRQN = SUITE / "trained" / "guided-upr24" / "paper"
"""The main job's 3 seeds (trained on ``paper``), played at each size (transfer.csv)."""
SIZES = {"paper": 8, "n16": 16, "n32": 32, "n64": 64}
REGISTERED = ("do-nothing", "random", "oracle", "identify-and-plan")


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def suite_row(file: str, task: str) -> dict:
    return next(r for r in read_csv(SUITE / file) if r["task"] == task and r["split"] == "test")


def returns() -> dict[tuple[int, str], tuple[float, float]]:
    """(n, controller) -> (test mean return, normalised) from the committed rows."""
    found = {}
    for task, n in SIZES.items():
        if task == "n64":
            for r in read_csv(HERE / "n64.csv"):
                found[n, r["controller"]] = float(r["mean_return"]), float(r["normalised"])
            continue
        for controller in REGISTERED:
            r = suite_row(f"{controller}.csv", task)
            name = "identify-and-plan (named)" if controller == "identify-and-plan" else controller
            found[n, name] = float(r["mean_return"]), float(r["normalised"])
        seeds = [next(r for r in read_csv(path) if r["task"] == task)
                 for path in sorted(TDRQN.glob("seed=*/transfer.csv"))]  # fmt: skip
        found[n, "TDRQN, compiled"] = (
            np.mean([float(r["mean_return"]) for r in seeds]),
            np.mean([float(r["normalised"]) for r in seeds]),
        )
        r = next(r for r in read_csv(AMORTISED / "test.csv") if r["task"] == task)
        found[n, "amortised controller"] = float(r["mean_return"]), float(r["normalised"])
    for r in read_csv(HERE / "fast.csv"):
        found[int(r["n_neurons"]), "identify-and-plan, fast form"] = (
            float(r["mean_return"]), float(r["normalised"]))
    return found


def rows() -> list[dict]:
    """One dict per (size, controller) of times.csv: n, controller, mean_return,
    normalised (NaN where no trained model of that size was played), p50, p99."""
    scores = returns()
    table = []
    for r in read_csv(HERE / "times.csv"):
        n = int(r["n_neurons"])
        mean, normalised = scores.get((n, r["controller"]), (np.nan, np.nan))
        table.append({"n": n, "controller": r["controller"], "mean_return": mean,
                      "normalised": normalised, "p50": float(r["decision_p50_ms"]),
                      "p99": float(r["decision_p99_ms"])})  # fmt: skip
    return table


def markdown(table: list[dict]) -> str:
    lines = ["| n | controller | test mean return | normalised | decision CPU ms, p50 | p99 |",
             "|---:|---|---:|---:|---:|---:|"]  # fmt: skip
    for r in sorted(table, key=lambda r: (r["n"], -np.nan_to_num(r["mean_return"]))):
        score = ("not played | –" if np.isnan(r["mean_return"])
                 else f"{r['mean_return']:.3f} | {r['normalised']:.3f}")  # fmt: skip
        lines.append(f"| {r['n']} | {r['controller']} | {score} | {r['p50']:.3g} | "
                     f"{r['p99']:.3g} |")  # fmt: skip
    return "\n".join(lines)


def paired() -> str:
    """The fast form against the named identify-and-plan, network by network."""
    lines = ["| n | fast form − named, per network [95%] | better / worse |", "|---:|---|---|"]
    fast = read_csv(HERE / "fast-per-network.csv")
    for task, n in SIZES.items():
        if task == "n64":
            continue
        named = sorted((r for r in read_csv(SUITE / "identify-and-plan-per-network.csv")
                        if r["task"] == task and r["split"] == "test"),
                       key=lambda r: int(r["context"]))  # fmt: skip
        mine = sorted((r for r in fast if r["task"] == task), key=lambda r: int(r["context"]))
        difference = (np.array([float(r["return"]) for r in mine])
                      - np.array([float(r["return"]) for r in named]))  # fmt: skip
        lines.append(f"| {n} | {paired_difference_cells(difference)} |")
    return "\n".join(lines)


def figure(table: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    controllers = sorted({r["controller"] for r in table})
    markers = dict(zip(controllers, "osD^vP*Xh<>", strict=False))
    colours = {name: f"C{i}" for i, name in enumerate(controllers)}  # the same in every panel
    fig, axes = plt.subplots(1, len(SIZES), figsize=(4.2 * len(SIZES), 4), sharey=True)
    for axis, n in zip(axes, SIZES.values(), strict=True):
        for r in (r for r in table if r["n"] == n and not np.isnan(r["normalised"])):
            axis.scatter(r["p99"], r["normalised"], marker=markers[r["controller"]],
                         color=colours[r["controller"]], label=r["controller"])  # fmt: skip
        axis.axvline(1.0, color="grey", linestyle=":")
        axis.set(xscale="log", title=f"n = {n}", xlabel="decision CPU time, p99 (ms)")
    axes[0].set_ylabel("normalised test score (0: do nothing, 1: oracle)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    fig.savefig(HERE / "tradeoff.png", dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", action="store_true")
    args = parser.parse_args()
    table = rows()
    print(markdown(table))
    print()
    print(paired())
    if args.figure:
        figure(table)


if __name__ == "__main__":
    main()
