"""The table of docs/training.md's "Learners that beat the planner?", from committed runs.

    python lab/results/guided_table.py docs/results

Per group (every trial on one Torch thread, on the project's 2-core AMD EPYC machine,
without AVX-512 but for the groups that say so): final validation and test return
(mean ± sd over seeds, ddof 0), the test IQM with its 95% stratified-bootstrap
interval, the network selected on the validation set (the evaluation with the highest
validation return) scored on the test set, and core-minutes (process CPU time) in all
and in the teacher.
"""

import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import bootstrap_ci, iqm
from spikectl.experiments.sweep import trial_dirs
from spikectl.training.run import best_on_validation
from spikectl.training.run_files import read_metrics

GROUPS = {
    "TDRQN, quick preset, committed (made on another CPU kind)": "learn-fast-pooled-decay",
    "TDRQN, quick preset (`spikectl train quick`)": "quick-this-machine",
    "guided, weaned to 0 (the guided preset until 2026-11-24)": "guided-identify",
    "guided, teacher told the weights (pilot, 1 seed)": "guided-told-weights-pilot",
    "guided, teacher identify-and-plan compiled (2026-11-24; the same numbers)": "guided-compiled",
    "guided, teacher plays 50% → 0 of the episodes (`--teacher-episodes 0.5`)": "guided-mix50",
    "guided, imitation floor 0.2 (the main job before the connectivity loss)": "guided-floor20",
    "guided, floor 0.2 and teacher plays 50% → 0": "guided-floor20-mix50",
    "guided, imitation floor 0.5": "guided-floor50",
    "guided, floor 0.2 and teacher plays 50% → 0, 4x the steps": "guided-floor20-mix50-4x",
    "guided + connectivity loss 0.1 (the main job until 2026-11-24, fourth stop)": "guided-conn01",
    "guided + connectivity loss 1": "guided-conn1",
    "guided + connectivity loss 0.1, 4x the steps": "guided-conn01-4x",
    "guided + connectivity loss, 28 updates a round": "guided-upr28",
    "guided + connectivity loss, 24 updates a round (the main job until 2026-11-25, 100 networks)":
        "guided-upr24",
    "the 100-network main job again, on an AMD EPYC with AVX-512 (2026-11-25)":
        "guided-upr24-avx512",
    "the 100-network main job + the others' spikes in the input (AVX-512 host)": "guided-others",
    "the main job on 1 000 training networks (`spikectl train guided`, AVX-512 host)":
        "guided-ntrain1000",
    "the main job on 4 000 training networks, 4x the steps (AVX-512 host)": "guided-ntrain4000-4x",
    "the main job with a 128-wide LSTM (pilot, 2 seeds, AVX-512 host)": "guided-lstm128",
    "PQN (`spikectl train pqn`)": "pqn",
    "the main job, this host (`spikectl train guided`)": "cleo-sim-to-sim:tdrqn-seed*",
    "the main job + the target's proximity in the input": "proximity-input:trials/n8/seed=*",
    "the main job + its teacher's belief in the input": "belief-input:trials/n8-seed*",
    "the main job + the planner's next action in the input": "advice-input:trials/n8-seed*",
    "the same, imitation annealed to 0 (reward alone)": "advice-input:trials/n8-rl-seed*",
    "ADVISOR, alpha 4": "advisor:trials/identify-a4-end1-seed*",
    "ADVISOR's control: policy head, imitation held at 1 (pilot)":
        "advisor:trials/identify-a0-end1-seed*",
    "the main job + a privileged critic (`--asymmetric-critic`)": "asymmetric-critic:trials/seed=*",
}
"""Row label -> results folder (its trials/), or ``folder:glob`` for the run directories
under the folder that match the glob."""


def runs_of(results: Path, group: str) -> list[Path]:
    """The run directories (those with a config.json) of a :data:`GROUPS` entry."""
    folder, _, pattern = group.partition(":")
    if not pattern:
        return trial_dirs(results / folder)
    return sorted(run for run in (results / folder).glob(pattern) if (run / "config.json").exists())


def mean_sd(values) -> str:
    return f"{np.mean(values):.3f} ± {np.std(values):.3f}"


def main(results: Path) -> None:
    print("| learner | seeds | final val | final test | test IQM [95% CI] | selected on val: "
          "test | core-minutes | of which teacher |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for label, group in GROUPS.items():
        if not runs_of(results, group):
            continue
        runs = [read_metrics(run) for run in runs_of(results, group)]  # research learners too
        final = [metrics[-1] for metrics in runs]
        selected = [best_on_validation(metrics) for metrics in runs]
        tests = np.array([row["test_return"] for row in final])
        interval = bootstrap_ci(tests, iqm, rng=0)
        teacher = [row.get("teacher_seconds", 0.0) / 60 for row in final]
        print(
            f"| {label} | {len(runs)} | {mean_sd([r['val_return'] for r in final])} | "
            f"{mean_sd(tests)} | "
            f"{interval.estimate:.3f} [{interval.low:.3f}, {interval.high:.3f}] | "
            f"{mean_sd([r['test_return'] for r in selected])} | "
            f"{np.mean([r['cpu_time_s'] for r in final]) / 60:.1f} | {np.mean(teacher):.1f} |"
        )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
