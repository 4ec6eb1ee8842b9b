"""The tables of README.md: each ADVISOR run's validation return during training, its
teacher agreement and mean ADVISOR weight, against the README's main job (the same
preset with DQfD's imitation alone, ``guided-ntrain1000``) and, for the teacher told the
weights, against that teacher's plain pilot (``guided-told-weights-pilot``).

    python lab/results/advisor/table.py

With three seeds of ``identify-a4-end1``, also their mean against the main job's and,
network by network on the test set, their best models (``trials/NAME/per_network.csv``,
written by ``benchmark.py``; each network's return averaged over the seeds) against
identify-and-plan's committed row.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from result_tables import PLANNER_TEST, best, metrics, per_network  # noqa: E402

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "advisor"
RESULTS = HERE.parent
MAIN_JOB = sorted((RESULTS / "guided-ntrain1000" / "trials").glob("seed=*"))
TOLD_WEIGHTS = sorted((RESULTS / "guided-told-weights-pilot" / "trials").glob("seed=*"))
EPISODES = (400, 800, 1200, 1600, 2400, 3200, 4000, 4400)
SEEDED = "identify-a4-end1"
"""The ADVISOR setting run with three seeds (the others are one-seed pilots)."""


def cell(rows: dict[int, dict], episode: int, field: str) -> str:
    value = rows.get(episode, {}).get(field, "")
    return "" if value in ("", "nan") else f"{float(value):.3f}"


def main() -> None:
    runs = {f"main job, seed {f.name[5:]}": f for f in MAIN_JOB}
    runs |= {f"told weights, plain, seed {f.name[5:]}": f for f in TOLD_WEIGHTS}
    runs |= {f.name: f for f in sorted((HERE / "trials").glob("*"))}
    print("Validation return during training (teacher agreement)\n")
    print("| episode | " + " | ".join(runs) + " |")
    print("|---:|" + "---:|" * len(runs))
    for episode in EPISODES:
        cells = []
        for folder in runs.values():
            rows = metrics(folder)
            value = cell(rows, episode, "val_return")
            agreement = cell(rows, episode, "teacher_agreement")
            cells.append(f"{value} ({agreement})" if agreement else value)
        print(f"| {episode} | " + " | ".join(cells) + " |")
    print("\n| run | best validation (episode) | ADVISOR weight at the end | test return at the"
          " best | core-minutes |")  # fmt: skip
    print("|---|---:|---:|---:|---:|")
    for name, folder in runs.items():
        rows = metrics(folder)
        chosen = best(folder)
        last = rows[max(rows)]
        weight = cell(rows, max(rows), "advisor_weight") or "–"
        print(
            f"| {name} | {float(chosen['val_return']):.3f} ({chosen['episode']}) | {weight} "
            f"| {float(chosen['test_return']):.3f} | {float(last['cpu_time_s']) / 60:.1f} |"
        )
    print(
        f"\nMain job, mean over its {len(MAIN_JOB)} seeds at the end: validation "
        f"{np.mean([float(metrics(f)[4400]['val_return']) for f in MAIN_JOB]):.3f}"
    )
    seeded = sorted((HERE / "trials").glob(f"{SEEDED}-seed*"))
    if len(seeded) >= 3:
        print_seeds({f"ADVISOR, alpha 4 ({SEEDED})": seeded, "main job": MAIN_JOB})
        print_paired(seeded)


def print_seeds(groups: dict[str, list[Path]]) -> None:
    """Mean ± sd over seeds: validation at the end, best validation, test return there."""
    print("\n| | seeds | validation at the end | best validation | test return of the best |")
    print("|---|---:|---:|---:|---:|")
    for name, folders in groups.items():
        ends, bests, tests = [], [], []
        for folder in folders:
            rows = metrics(folder)
            chosen = best(folder)
            ends.append(float(rows[max(rows)]["val_return"]))
            bests.append(float(chosen["val_return"]))
            tests.append(float(chosen["test_return"]))
        print(f"| {name} | {len(folders)} | {spread(ends)} | {spread(bests)} | {spread(tests)} |")


def spread(values: list[float]) -> str:
    each = " / ".join(f"{v:.3f}" for v in values)
    return f"{np.mean(values):.3f} ± {np.std(values, ddof=1):.3f} ({each})"


def print_paired(seeded: list[Path]) -> None:
    learned = np.mean(
        [per_network(folder / "per_network.csv", "paper") for folder in seeded], axis=0
    )
    planner = per_network(PLANNER_TEST, "paper")
    print("\nThe paper task's test networks, network by network (the seeds' mean on each)\n")
    print("| | seeds | learned − planner | mean difference [95% CI] | better / worse |")
    print("|---|---:|---:|---:|---:|")
    print(f"| ADVISOR, alpha 4 − identify-and-plan | {len(seeded)} "
          f"| {learned.mean():.3f} − {planner.mean():.3f} "
          f"| {paired_difference_cells(learned - planner)} |")  # fmt: skip


if __name__ == "__main__":
    main()
