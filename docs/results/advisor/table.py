"""The tables of README.md: each ADVISOR run's validation return during training, its
teacher agreement and mean ADVISOR weight, against the README's main job (the same
preset with DQfD's imitation alone, ``guided-ntrain1000``) and, for the teacher told the
weights, against that teacher's plain pilot (``guided-told-weights-pilot``).

    python docs/results/advisor/table.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
RESULTS = HERE.parent
MAIN_JOB = sorted((RESULTS / "guided-ntrain1000" / "trials").glob("seed=*"))
TOLD_WEIGHTS = sorted((RESULTS / "guided-told-weights-pilot" / "trials").glob("seed=*"))
EPISODES = (400, 800, 1200, 1600, 2400, 3200, 4000, 4400)


def metrics(folder: Path) -> dict[int, dict]:
    with open(folder / "metrics.csv", newline="") as handle:
        return {int(row["episode"]): row for row in csv.DictReader(handle)}


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
        chosen = max(rows.values(), key=lambda row: float(row["val_return"]))
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


if __name__ == "__main__":
    main()
