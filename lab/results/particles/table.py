"""The particle posterior against the Gaussian estimate on the n16 and n32 validation
networks, network by network, in the three forms the Gaussian one was measured in: the
constructor's defaults, the fast form (``known_sd`` 0.4, the guided learner's teacher)
and the named controller (QMDP where it would probe, ``known_sd`` 0.35). Mean difference
with a 95% bootstrap interval over the 100 networks (10 000 resamples, seed 0).

    python lab/results/particles/table.py > docs/results/particles/table.md
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "particles"
GAUSSIAN = HERE.parent / "bayes-identify"
FORMS = (  # (form, Gaussian setting, the sweep it was in at n16 and n32, particle setting)
    ("constructor's defaults", {}, ("validation-sweep12",) * 2, {}),
    ("fast (`known_sd` 0.4)", {"known_sd": 0.4}, ("validation-sweep12",) * 2, {"known_sd": 0.4}),
    ("named (QMDP, `known_sd` 0.35)", {"named": True, "known_sd": 0.35},
     ("validation-sweep9", "validation-sweep11"), {"named": True}),
)  # fmt: skip
PARTICLES = {"identification": "particles"}


def key(settings: dict) -> str:
    return json.dumps(settings, sort_keys=True)


def rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def matches(row: dict, task: str, settings: dict) -> bool:
    return row["task"] == task and key(json.loads(row["settings"])) == key(settings)


def returns(path: Path, task: str, settings: dict) -> np.ndarray:
    """[100] the returns of ``settings`` on ``task``'s validation networks 0..99."""
    found = [row for row in rows(path) if matches(row, task, settings)]
    if [int(row["context"]) for row in found] != list(range(100)):
        raise SystemExit(f"{path} lacks the 100 networks of {task} {settings}")
    return np.array([float(row["return"]) for row in found])


def summary(path: Path, task: str, settings: dict) -> dict:
    for row in rows(path):
        if matches(row, task, settings):
            return row
    raise SystemExit(f"{path} has no row for {task} {settings}")


def main() -> None:
    print(
        "| task | form | Gaussian | particles | particles − Gaussian [95% CI] | better / worse "
        "networks | CPU s / episode (G / p) | decision p99 ms (G / p) |"
    )
    print("|---|---|---:|---:|---|---|---|---|")
    for size, task in enumerate(("n16", "n32")):
        for form, gaussian, sweeps, particle in FORMS:
            sweep = sweeps[size]
            named = "named-" if particle.get("named") else ""
            ours = HERE / f"validation-{named}{task}"
            particle = {**particle, **PARTICLES}
            old = returns(GAUSSIAN / f"{sweep}-per-network.csv", task, gaussian)
            new = returns(ours.with_name(ours.name + "-per-network.csv"), task, particle)
            a = summary(GAUSSIAN / f"{sweep}.csv", task, gaussian)
            b = summary(ours.with_suffix(".csv"), task, particle)
            print(
                f"| `{task}` | {form} | {old.mean():.3f} | {new.mean():.3f} | "
                f"{paired_difference_cells(new - old)} | "
                f"{float(a['cpu_s_per_episode']):.2f} / {float(b['cpu_s_per_episode']):.2f} | "
                f"{float(a['decision_cpu_ms_p99']):.0f} / {float(b['decision_cpu_ms_p99']):.0f} |"
            )
    named, train = {"named": True}, HERE / "train-n32-per-network.csv"
    old = returns(train, "n32", {**named, "identification": "gaussian"})
    new = returns(train, "n32", {**named, **PARTICLES})
    pooled = [new - old]
    print(
        f"\nThe choice checked on the first 100 `n32` training networks (both in one run), "
        f"then the `n32` test set played once (`spikectl benchmark identify-and-plan --task "
        f"n32`, against the named controller's rows before):\n\n"
        f"| networks | Gaussian | particles | particles − Gaussian [95% CI] | better / worse |\n"
        f"|---|---:|---:|---|---|\n"
        f"| `n32` training (100) | {old.mean():.3f} | {new.mean():.3f} | "
        f"{paired_difference_cells(new - old)} |"
    )
    old, new = (test_returns(HERE / name) for name in ("test-before-per-network.csv",
                                                       "test-per-network.csv"))  # fmt: skip
    pooled_test = new - old
    print(
        f"| `n32` test (100) | {old.mean():.3f} | {new.mean():.3f} | "
        f"{paired_difference_cells(new - old)} |"
    )
    old = returns(GAUSSIAN / "validation-sweep11-per-network.csv", "n32", FORMS[2][1])
    new = returns(HERE / "validation-named-n32-per-network.csv", "n32", {**named, **PARTICLES})
    pooled = np.concatenate([*pooled, new - old, pooled_test])
    print(f"| `n32` validation, training and test (300) | | | {paired_difference_cells(pooled)} |")


def test_returns(path: Path) -> np.ndarray:
    """[100] the `n32` returns in a ``spikectl benchmark --per-network`` CSV."""
    found = [row for row in rows(path) if row["task"] == "n32"]
    if [int(row["context"]) for row in found] != list(range(100)):
        raise SystemExit(f"{path} lacks the 100 networks of n32")
    return np.array([float(row["return"]) for row in found])


if __name__ == "__main__":
    main()
