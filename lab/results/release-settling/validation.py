"""Identify-and-plan on the ``stochastic`` task's train and validation sets (never the
test set), network by network: the named controller with each spike's release chance as
the Gaussian estimate's evidence (lab/planners' ``ReleaseChanceEvidence``, what it played
before) and
with each release settled from the next step's residuals (the named controller now), at
the ``known_sd`` of each; and how right the known weights are at steps 10, 30 and 59.

    python lab/results/release-settling/validation.py docs/results/release-settling

Writes ``validation-per-network.csv`` and prints the tables of ``validation-table.txt``.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners import ReleaseChanceEvidence
from lab.planners.recording import RecordingIdentifyAndPlan as Checked
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import EstimatorSettings, named_composition

TASK = "stochastic"
SPLITS = ("train", "validation")
CHECKED_STEPS = Checked.checked_steps


def main(out: Path) -> None:
    extensions = suite.task(TASK).extensions
    named = named_composition(extensions, 8)
    variants = {
        "release chance (before)": named.but("release-chances",
                                             observation=ReleaseChanceEvidence(task_model=True)),
        "settled releases (now)": named,
        "settled releases, known_sd 0.3": named.but("known-sd-0.3",
                                                    estimator=EstimatorSettings(known_sd=0.3)),
    }  # fmt: skip
    rows, returns, knowledge = [], {}, {}
    for label, composition in variants.items():
        record: list = []
        played, cpu = [], 0.0
        for split in SPLITS:
            contexts = suite.load_split(TASK, split)
            policy = Checked(contexts, record, composition=composition, extensions=extensions)
            values, seconds = suite.play(TASK, split, policy)
            played.append(values)
            cpu += seconds
            rows += [{"controller": label, "split": split, "context": index,
                      "return": float(value)} for index, value in enumerate(values)]  # fmt: skip
        returns[label] = (np.concatenate(played), cpu)
        knowledge[label] = np.array(record)
    with open(out / "validation-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    before = returns["release chance (before)"][0]
    print(f"Train + validation ({before.size} networks), network by network:\n")
    print("| evidence | mean return | − before [95% CI] | better / worse | CPU s |")
    print("|---|---:|---|---|---:|")
    for label, (played, cpu) in returns.items():
        print(f"| {label} | {played.mean():.3f} | {paired_difference_cells(played - before)} "
              f"| {cpu:.1f} |")  # fmt: skip
    print("\nKnown weights (off the diagonal): share known / share of those right\n")
    print("| evidence | " + " | ".join(f"step {step}" for step in CHECKED_STEPS) + " |")
    print("|---|" + "---:|" * len(CHECKED_STEPS))
    for label, record in knowledge.items():
        cells = []
        for step in CHECKED_STEPS:
            at = record[record[:, 0] == step]
            cells.append(f"{at[:, 1].mean():.2f} / {at[:, 2].mean():.3f}")
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
