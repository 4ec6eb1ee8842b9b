"""The tables of docs/results/asymmetric-critic/README.md, from committed files only.

    python lab/results/asymmetric-critic/table.py > docs/results/asymmetric-critic/table.md

The README's main job with the privileged critic (trials/seed=S) against the main job's
committed seeds on the same CPU kind (../cleo-sim-to-sim/tdrqn-seedS, the same preset
without it, AVX2; those of ../guided-ntrain1000 ran with AVX-512): the
validation return each metrics.csv records during training, the end's and the best
evaluation's validation return, the test return recorded at the best (the run's
best_model.pt), the teacher agreement at the end and core-minutes. Then the seeds' mean
on each of the paper task's 100 test networks (``spikectl benchmark --per-network``)
against the named identify-and-plan's committed rows, network by network
(``spikectl.experiments.stats.paired_difference_cells``).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells
from spikectl.training.run import best_on_validation
from spikectl.training.run_files import read_metrics

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "asymmetric-critic"
RESULTS = HERE.parent
GROUPS = {
    "with the critic": sorted((HERE / "trials").glob("seed=*")),
    "the main job": sorted((RESULTS / "cleo-sim-to-sim").glob("tdrqn-seed*")),
}
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # result_tables
from result_tables import PLANNER_TEST, PLANNER_VALIDATION  # noqa: E402


def test_returns(path: Path) -> np.ndarray:
    """[100] the return on each of the paper task's test networks in a per-network CSV."""
    with open(path, newline="") as handle:
        table = [row for row in csv.DictReader(handle) if row["task"] == "paper"]
    if sorted(int(row["context"]) for row in table) != list(range(100)):
        raise ValueError(f"{path} lacks the paper task's 100 test networks")
    return np.array(
        [float(row["return"]) for row in sorted(table, key=lambda r: int(r["context"]))]
    )


def spread(values: list[float]) -> str:
    each = " / ".join(f"{v:.3f}" for v in values)
    return f"{np.mean(values):.3f} ± {np.std(values):.3f} ({each})"


def main() -> None:
    runs = {label: [read_metrics(seed) for seed in seeds] for label, seeds in GROUPS.items()}
    print("Validation return during training (mean over seeds; identify-and-plan "
          f"{PLANNER_VALIDATION['paper']})\n")  # fmt: skip
    print("| episode | " + " | ".join(runs) + " | critic's TD loss |")
    print("|---:|" + "---:|" * (len(runs) + 1))
    for index, row in enumerate(runs["with the critic"][0]):
        cells = [f"{np.mean([seed[index]['val_return'] for seed in metrics]):.3f}"
                 for metrics in runs.values()]  # fmt: skip
        critic = np.mean([seed[index]["critic_loss"] for seed in runs["with the critic"]])
        print(f"| {int(row['episode'])} | " + " | ".join(cells) + f" | {critic:.5f} |")
    print(
        "\n| | seeds | validation at the end | best validation | test return of the best "
        "| teacher agreement at the end | core-minutes |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for label, metrics in runs.items():
        best = [best_on_validation(seed) for seed in metrics]
        print(f"| {label} | {len(metrics)} | {spread([s[-1]['val_return'] for s in metrics])} "
              f"| {spread([b['val_return'] for b in best])} "
              f"| {spread([b['test_return'] for b in best])} "
              f"| {np.mean([s[-1]['teacher_agreement'] for s in metrics]):.3f} "
              f"| {np.mean([s[-1]['cpu_time_s'] for s in metrics]) / 60:.1f} |")  # fmt: skip
    files = [seed / "per_network.csv" for seed in GROUPS["with the critic"]]
    learned = np.mean([test_returns(path) for path in files], axis=0)  # [100]
    planner = test_returns(PLANNER_TEST)
    print("\nThe paper task's test networks, network by network (the seeds' mean on each)\n")
    print("| | seeds | learned − planner | mean difference [95% CI] | better / worse |")
    print("|---|---:|---:|---:|---:|")
    print(
        f"| with the critic − identify-and-plan | {len(files)} | {learned.mean():.3f} − "
        f"{planner.mean():.3f} | {paired_difference_cells(learned - planner)} |"
    )


if __name__ == "__main__":
    main()
