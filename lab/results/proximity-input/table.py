"""The tables of README.md: the guided learner with the target's proximity as an input
(``--sizes.inputs target proximity``) against the same preset without it, by the validation
return its metrics.csv records during training and the test return recorded at its best
validation return (its best model).

    python lab/results/proximity-input/table.py   # also draws curves.png

The runs without it are the committed main job (``guided-ntrain1000``, n = 8) and the
suite's learned rows (``suite/trained/guided-upr24/n16``, ``n32``): the same preset and
flags. Network by network on the test set: each seed's best model played on the suite
task's 100 test networks (``spikectl benchmark RUN --model best --task T --per-network
trials/SIZE/seed=S/per_network.csv``), the seeds' mean on each network against
identify-and-plan's committed rows (``bayes-identify/test-benchmark-known-sd-per-network.csv``,
the named controller of the suite's leaderboard on these tasks) and, at 32 neurons,
against the runs without the input (their committed ``per_network.csv``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from result_tables import PLANNER_TEST, PLANNER_VALIDATION, best, metrics, per_network  # noqa: E402

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "proximity-input"
RESULTS = HERE.parent
WITHOUT = {
    "n8": RESULTS / "guided-ntrain1000" / "trials",
    "n16": RESULTS / "suite" / "trained" / "guided-upr24" / "n16",
    "n32": RESULTS / "suite" / "trained" / "guided-upr24" / "n32",
}
TASKS = {"n8": "paper", "n16": "n16", "n32": "n32"}
"""The suite task whose test set each size's per_network.csv holds."""
EPISODES = (800, 1600, 2400, 3200, 4000, 4400)


def paired_rows(groups: dict[str, dict[str, list[Path]]]) -> None:
    """Network by network on the test set (the seeds' mean on each network)."""
    print("\nNetwork by network on the test set (each network's return averaged over the"
          " seeds first)\n")  # fmt: skip
    print("| size | comparison | seeds | mean returns | difference [95% CI] | better / worse |")
    print("|---|---|---|---|---|---|")
    for size, runs in groups.items():
        task = TASKS[size]
        files = [f / "per_network.csv" for f in runs["with"] if (f / "per_network.csv").exists()]
        if not files:
            continue
        learned = np.mean([per_network(f, task) for f in files], axis=0)  # [100]
        planner = per_network(PLANNER_TEST, task)
        print(f"| {size} | with − identify-and-plan | {len(files)} "
              f"| {learned.mean():.3f} − {planner.mean():.3f} "
              f"| {paired_difference_cells(learned - planner)} |")
        without_files = [f / "per_network.csv" for f in runs["without"]]
        if all(f.exists() for f in without_files):
            without = np.mean([per_network(f, task) for f in without_files], axis=0)
            print(f"| {size} | with − without | {len(files)}, {len(without_files)} "
                  f"| {learned.mean():.3f} − {without.mean():.3f} "
                  f"| {paired_difference_cells(learned - without)} |")  # fmt: skip


def plot(groups: dict[str, dict[str, list[Path]]]) -> None:
    """curves.png: validation return against episodes, each run, one panel a size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(groups), figsize=(5 * len(groups), 3.6))
    for ax, (size, runs) in zip(axes, groups.items(), strict=True):
        for (label, folders), colour in zip(runs.items(), ("tab:red", "tab:gray"), strict=True):
            for index, folder in enumerate(folders):
                rows = metrics(folder)
                name = f"{label} the proximity input" if index == 0 else None
                values = [float(r["val_return"]) for r in rows.values()]
                ax.plot(list(rows), values, color=colour, alpha=0.8, label=name)
        ax.axhline(PLANNER_VALIDATION[TASKS[size]], color="black", linestyle="--", linewidth=1,
                   label="identify-and-plan")  # fmt: skip
        ax.set(title=f"{size}: the guided learner", xlabel="episode", ylabel="validation return")
        ax.legend(loc="lower right")
    figure.tight_layout()
    figure.savefig(HERE / "curves.png", dpi=120)


def main() -> None:
    groups = {}
    for size, baseline in WITHOUT.items():
        runs = {"with": sorted((HERE / "trials" / size).glob("seed=*")),
                "without": sorted(baseline.glob("seed=*"))}  # fmt: skip
        if not runs["with"]:
            continue
        groups[size] = runs
        print(f"\n{size}: validation return during training (mean over seeds, each seed)\n")
        print("| episode | " + " | ".join(f"{k} ({len(v)} seeds)" for k, v in runs.items()) + " |")
        print("|---:|---|---|")
        for episode in EPISODES:
            cells = []
            for folders in runs.values():
                values = [float(metrics(f)[episode]["val_return"]) for f in folders
                          if episode in metrics(f)]  # fmt: skip
                each = ", ".join(f"{v:.3f}" for v in values)
                cells.append(f"{np.mean(values):.3f} ({each})" if values else "")
            print(f"| {episode} | " + " | ".join(cells) + " |")
        print("\n| | best validation (mean ± sd) | test return there | core-minutes |")
        print("|---|---|---|---|")
        for label, folders in runs.items():
            chosen = [best(f) for f in folders]
            best_val = [float(row["val_return"]) for row in chosen]
            tests = [float(row["test_return"]) for row in chosen]
            cpu = [float(list(metrics(f).values())[-1]["cpu_time_s"]) / 60 for f in folders]
            sd = np.std(best_val, ddof=1) if len(best_val) > 1 else 0.0
            print(f"| {label} | {np.mean(best_val):.3f} ± {sd:.3f} "
                  f"| {np.mean(tests):.3f} ({', '.join(f'{t:.3f}' for t in tests)}) "
                  f"| {', '.join(f'{c:.1f}' for c in cpu)} |")  # fmt: skip
    paired_rows(groups)
    plot(groups)


if __name__ == "__main__":
    main()
