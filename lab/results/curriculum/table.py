"""The tables of README.md: a curriculum over sizes (n = 8, then the suite's n16, then
n32) against the n = 8 network played at the larger size without training (zero-shot),
against training there from scratch and against identify-and-plan.

    python lab/results/curriculum/table.py   # also draws curves.png

Every comparison is chosen or read on validation first; the test return is the best
model's (the evaluation with the highest validation return, which may be episode 0:
the starting weights). Network by network on the test set, each network's return is
first averaged over the three seeds. From scratch: ``../proximity-input`` (the same
preset with the proximity input, 4 400 episodes at each size; its teacher was the
constructor's identify-and-plan, the fine-tuning runs' the task's own, within noise of
each other at n16: ``../task-teacher``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from result_tables import PLANNER_TEST, PLANNER_VALIDATION, best, metrics, per_network  # noqa: E402

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "curriculum"
RESULTS = HERE.parent
SEEDS = (0, 1, 2)
STAGES = {"n16": "n16-imit", "n32": "n32-imit"}
"""The fine-tuning run of each size (its source: the n = 8 run, then the n16 stage)."""
SCRATCH = RESULTS / "proximity-input" / "trials"


def zero_shot(seed: int, split: str, task: str) -> np.ndarray:
    """[100] the n = 8 network of ``seed`` played on ``task``'s ``split`` set."""
    return per_network(HERE / "zero-shot" / f"n8-seed{seed}-{split}.csv", task)


def stage_runs(stage: str) -> list[Path]:
    return [HERE / "trials" / stage / f"seed={seed}" for seed in SEEDS
            if (HERE / "trials" / stage / f"seed={seed}" / "metrics.csv").exists()]  # fmt: skip


def cells(values: list[float]) -> str:
    sd = f" ± {np.std(values, ddof=1):.3f}" if len(values) > 1 else ""
    return f"{np.mean(values):.3f}{sd} ({', '.join(f'{v:.3f}' for v in values)})"


def curves(stage: str) -> None:
    runs = stage_runs(stage)
    episodes = sorted(set.intersection(*(set(metrics(run)) for run in runs)))
    print(f"\n`{stage}`: validation return (teacher agreement) by episode, each seed\n")
    print("| episode | " + " | ".join(f"seed {run.name[5:]}" for run in runs) + " |")
    print("|---:|" + "---|" * len(runs))
    for episode in episodes:
        row = [metrics(run)[episode] for run in runs]
        agreement = [r["teacher_agreement"] for r in row]
        print(f"| {episode} | " + " | ".join(
            f"{float(r['val_return']):.3f}" + (f" ({float(a):.2f})" if a != "nan" else "")
            for r, a in zip(row, agreement, strict=True)) + " |")  # fmt: skip


def print_best(task: str, label: str, runs: list[Path]) -> None:
    """One row: the runs' best validation returns, their test returns, their core-minutes."""
    chosen = [best(run) for run in runs]
    cpu = [float(list(metrics(run).values())[-1]["cpu_time_s"]) / 60 for run in runs]
    print(f"| {task} | {label} | {cells([float(r['val_return']) for r in chosen])} | "
          f"{cells([float(r['test_return']) for r in chosen])} | "
          f"{', '.join(f'{c:.1f}' for c in cpu)} |")  # fmt: skip


def summary() -> None:
    print("\nEach size: validation and test return (mean ± sd over seeds, each seed)\n")
    print("| size | controller | validation | test | core-minutes a run |")
    print("|---|---|---|---|---|")
    for task, stage in STAGES.items():
        runs = stage_runs(stage)
        if not runs:
            continue
        zero_val = [zero_shot(s, "validation", task).mean() for s in SEEDS]
        zero_test = [zero_shot(s, "test", task).mean() for s in SEEDS]
        print(f"| {task} | n = 8 network, zero-shot | {cells(zero_val)} | {cells(zero_test)} | 0 |")
        print_best(task, "curriculum (best model)", runs)
        print_best(task, "from scratch (best model)", [SCRATCH / task / f"seed={s}" for s in SEEDS])
        print(f"| {task} | identify-and-plan | {PLANNER_VALIDATION[task]:.3f} | "
              f"{per_network(PLANNER_TEST, task).mean():.3f} | |")


def paired() -> None:
    print("\nNetwork by network on the test set (each network's return averaged over the"
          " seeds first)\n")  # fmt: skip
    print("| size | comparison | mean returns | difference [95% CI] | better / worse |")
    print("|---|---|---|---|---|")
    for task, stage in STAGES.items():
        runs = stage_runs(stage)
        if len(runs) < len(SEEDS):
            continue
        learned = np.mean([per_network(run / "per_network.csv", task) for run in runs], axis=0)
        others = {
            "zero-shot from n = 8": np.mean([zero_shot(s, "test", task) for s in SEEDS], axis=0),
            "from scratch": np.mean(
                [per_network(SCRATCH / task / f"seed={s}" / "per_network.csv", task)
                 for s in SEEDS], axis=0),  # fmt: skip
            "identify-and-plan": per_network(PLANNER_TEST, task),
        }
        for name, other in others.items():
            print(f"| {task} | curriculum − {name} | {learned.mean():.3f} − {other.mean():.3f} "
                  f"| {paired_difference_cells(learned - other)} |")


def plot() -> None:
    """curves.png: validation return against episodes of each fine-tuning run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(STAGES), figsize=(10, 3.6))
    for ax, (task, stage) in zip(axes, STAGES.items(), strict=True):
        for index, run in enumerate(stage_runs(stage)):
            rows = metrics(run)
            label = "fine-tuned" if index == 0 else None
            ax.plot(list(rows), [float(r["val_return"]) for r in rows.values()],
                    color="tab:red", alpha=0.8, label=label)  # fmt: skip
        zero = np.mean([zero_shot(s, "validation", task).mean() for s in SEEDS])
        ax.axhline(zero, color="tab:blue", linewidth=1, label="n = 8 network, zero-shot")
        scratch = np.mean([float(best(SCRATCH / task / f"seed={s}")["val_return"]) for s in SEEDS])
        ax.axhline(scratch, color="tab:gray", linewidth=1, label="from scratch (best)")
        ax.axhline(PLANNER_VALIDATION[task], color="black", linestyle="--", linewidth=1,
                   label="identify-and-plan")  # fmt: skip
        ax.set(title=f"{task}: fine-tuning", xlabel="episode", ylabel="validation return")
    figure.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=4)
    figure.tight_layout(rect=(0, 0.08, 1, 1))
    figure.savefig(HERE / "curves.png", dpi=120)


def main() -> None:
    for stage in ("n16-imit", "n16-reward", "n32-imit"):
        if stage_runs(stage):
            curves(stage)
    summary()
    paired()
    plot()


if __name__ == "__main__":
    main()
