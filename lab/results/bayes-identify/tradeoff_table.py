"""Decision time against return: identify-and-plan's configurations on the `paper`, `n16`
and `n32` validation networks, from the committed sweeps (this folder's and
../particles/), one row per configuration: mean return, normalised score, CPU seconds
per episode and each decision's thread CPU time at the median and 99th percentile.

    python lab/results/bayes-identify/tradeoff_table.py

The rows were timed in different runs on the project's 2-core AMD EPYC (AVX2), one
thread, beside one or two other jobs: compare orders of magnitude, not percent.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "bayes-identify"
PARTICLES = HERE.parent / "particles"
ROWS = (  # (task, configuration, its settings as swept, the sweep's summary CSV)
    ("paper", "the constructor's defaults (named; real time)", {}, HERE / "validation-sweep12.csv"),
    ("n16", "the constructor's defaults", {}, HERE / "validation-sweep12.csv"),
    ("n16", "fast form: `known_sd` 0.4 (the guided learner's teacher)", {"known_sd": 0.4},
     HERE / "validation-sweep12.csv"),
    ("n16", "fast form with particles", {"identification": "particles", "known_sd": 0.4},
     PARTICLES / "validation-n16.csv"),
    ("n16", "QMDP over 16 drawn networks, `known_sd` 0.35 (named)",
     {"named": True, "known_sd": 0.35}, HERE / "validation-sweep9.csv"),
    ("n16", "the same with particles", {"named": True, "identification": "particles"},
     PARTICLES / "validation-named-n16.csv"),
    ("n32", "the constructor's defaults", {}, HERE / "validation-sweep12.csv"),
    ("n32", "fast form: `known_sd` 0.4 (the guided learner's teacher)", {"known_sd": 0.4},
     HERE / "validation-sweep12.csv"),
    ("n32", "fast form with particles", {"identification": "particles", "known_sd": 0.4},
     PARTICLES / "validation-n32.csv"),
    ("n32", "QMDP over 16 drawn networks, `known_sd` 0.35", {"named": True, "known_sd": 0.35},
     HERE / "validation-sweep11.csv"),
    ("n32", "the same with particles (named)", {"named": True, "identification": "particles"},
     PARTICLES / "validation-named-n32.csv"),
)  # fmt: skip


def summary(path: Path, task: str, settings: dict) -> dict:
    wanted = json.dumps(settings, sort_keys=True)
    with open(path, newline="") as handle:
        for row in csv.DictReader(handle):
            same = json.dumps(json.loads(row["settings"]), sort_keys=True) == wanted
            if row["task"] == task and same:
                return row
    raise SystemExit(f"{path} has no row for {task} {settings}")


def main() -> None:
    print("| task | configuration | return (normalised) | CPU s / episode "
          "| decision CPU ms, median / 99th percentile |")  # fmt: skip
    print("|---|---|---:|---:|---:|")
    for task, label, settings, path in ROWS:
        row = summary(path, task, settings)
        print(
            f"| `{task}` | {label} | {float(row['mean_return']):.3f} "
            f"({float(row['normalised']):.3f}) | {float(row['cpu_s_per_episode']):.2f} | "
            f"{float(row['decision_cpu_ms_p50']):.1f} / {float(row['decision_cpu_ms_p99']):.1f} |"
        )


if __name__ == "__main__":
    main()
