"""The table of docs/training.md's "Learners that beat the planner?", from committed runs.

    python docs/results/guided_table.py docs/results

Per group (every trial on one Torch thread, on the project's 2-core AMD EPYC machine,
without AVX-512 but for the two groups that say so): final validation and test return
(mean ± sd over seeds, ddof 0), the test IQM with its 95% stratified-bootstrap
interval, the network selected on the validation set (the evaluation with the highest
validation return) scored on the test set, and core-minutes (process CPU time) in all
and in the teacher.
"""

import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.report import load_runs
from spikectl.experiments.stats import bootstrap_ci, iqm
from spikectl.experiments.sweep import trial_dirs
from spikectl.training.run import best_on_validation

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
}


def mean_sd(values) -> str:
    return f"{np.mean(values):.3f} ± {np.std(values):.3f}"


def main(results: Path) -> None:
    print("| learner | seeds | final val | final test | test IQM [95% CI] | selected on val: "
          "test | core-minutes | of which teacher |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for label, folder in GROUPS.items():
        if not trial_dirs(results / folder):
            continue
        runs = load_runs(trial_dirs(results / folder))
        final = [run.metrics[-1] for run in runs]
        selected = [best_on_validation(run.metrics) for run in runs]
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
