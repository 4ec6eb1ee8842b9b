"""Identify-and-plan's filter under measurement noise, before and after it trusts the
paper's deterministic step exactly: the named controller and the same loop told the
weights, on the validation sets of ``noise1``, ``noise2`` and ``noise4`` (never the
test sets), network by network.

    python lab/results/exact-filter/validation.py docs/results/exact-filter

"before" is the filter with its constant 0.25 mV^2 per step (``MODEL_VARIANCE_MV2``, what
every environment got), "after" the filter as the package builds it now
(:func:`spikectl.planning.filtering.model_variance`: 0 under the paper's dynamics). Writes
``validation-per-network.csv`` and prints the table of ``validation.md``.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

import spikectl.planning.policy as policy_module
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning.filtering import MODEL_VARIANCE_MV2, model_variance
from spikectl.planning.policy import IdentifyAndPlan, environment_settings

TASKS = ("noise1", "noise2", "noise4")
SETTINGS = {"named": {}, "named, known_sd 0.45": {"known_sd": 0.45}}


class ToldTheWeights:
    """The loop told each validation network's weights (read from the set by the
    environment's ``context_index``): only the filter and the planning remain."""

    def __init__(self, task: str, **settings) -> None:
        self.contexts = suite.load_split(task, "validation")
        self.settings = settings
        self.policy: IdentifyAndPlan | None = None

    def reset(self) -> None:
        self.policy = None

    def act(self, observation, info) -> int:
        if int(observation["step"]) == 0:
            weights = self.contexts[int(info["context_index"])].weights
            self.policy = IdentifyAndPlan(known_weights=weights, **self.settings)
        return self.policy.act(observation, info)


def play(task: str, filter_kind: str, label: str) -> np.ndarray:
    extensions = suite.task(task).extensions
    settings = {**environment_settings(extensions, 8),
                "noise_mV": extensions.observation_noise_mV}  # fmt: skip
    # "before": every environment's filter adds MODEL_VARIANCE_MV2 per step.
    policy_module.model_variance = (
        (lambda _: MODEL_VARIANCE_MV2) if filter_kind == "before" else model_variance
    )
    try:
        if label == "told the weights":
            controller = ToldTheWeights(task, **settings)
        else:
            controller = IdentifyAndPlan(**{**settings, **SETTINGS[label]})
        returns, _ = suite.play(task, "validation", controller)
    finally:
        policy_module.model_variance = model_variance
    return returns


def main(out: Path) -> None:
    rows, returns = [], {}
    cases = [("before", "named"), ("after", "named"), ("before", "told the weights"),
             ("after", "told the weights"), ("after", "named, known_sd 0.45")]  # fmt: skip
    for task in TASKS:
        for filter_kind, label in cases:
            played = play(task, filter_kind, label)
            returns[task, filter_kind, label] = played
            rows += [{"task": task, "filter": filter_kind, "controller": label,
                      "context": index, "return": float(value)}
                     for index, value in enumerate(played)]  # fmt: skip
    with open(out / "validation-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print("| task | controller | before | after | after − before [95% CI] | better / worse |")
    print("|---|---|---:|---:|---|---|")
    for label in ("named", "told the weights"):
        pooled = []
        for task in TASKS:
            before, after = returns[task, "before", label], returns[task, "after", label]
            pooled.append(after - before)
            print(f"| `{task}` | {label} | {before.mean():.3f} | {after.mean():.3f} | "
                  f"{paired_difference_cells(after - before)} |")  # fmt: skip
        print(f"| all three | {label} | | | {paired_difference_cells(np.concatenate(pooled))} |")
    pooled = []
    for task in TASKS:
        after = returns[task, "after", "named"]
        sooner = returns[task, "after", "named, known_sd 0.45"]
        pooled.append(sooner - after)
        print(f"| `{task}` | named, known_sd 0.45 against named (after) | {after.mean():.3f} | "
              f"{sooner.mean():.3f} | {paired_difference_cells(sooner - after)} |")  # fmt: skip
    print(f"| all three | known_sd 0.45 against named | | | "
          f"{paired_difference_cells(np.concatenate(pooled))} |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
