"""Identify-and-plan on the ``heterogeneous`` task's validation set (never the test set),
network by network: the constructor's defaults (what the named controller played
before), the named controller now (each neuron's threshold and leak learned, known
synapses planned at their estimated strength) and each half alone.

    python lab/results/heterogeneous-neurons/validation.py docs/results/heterogeneous-neurons

Writes ``validation-per-network.csv`` and prints the table of ``validation-table.txt``.
"""

from __future__ import annotations

import csv
import dataclasses
import sys
from pathlib import Path

from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import Composition, IdentifyAndPlan, ObservationSettings, named_composition

TASK = "heterogeneous"
TASK_MODEL = Composition("task-model", observation=ObservationSettings(task_model=True))


def main(out: Path) -> None:
    extensions = suite.task(TASK).extensions
    controllers = {
        "before: the constructor's defaults": IdentifyAndPlan(),
        "after: the named controller": IdentifyAndPlan(
            composition=named_composition(extensions, 8), extensions=extensions),
        "thresholds and leaks learned, synapses as signs": IdentifyAndPlan(
            composition=TASK_MODEL,
            extensions=dataclasses.replace(extensions, synaptic_spread=0.0)),
        "synapses at their strength, the paper's neurons": IdentifyAndPlan(
            composition=TASK_MODEL,
            extensions=dataclasses.replace(extensions, threshold_spread=0.0,
                                           time_constant_spread=0.0)),
    }  # fmt: skip
    returns, rows = {}, []
    for label, controller in controllers.items():
        played, cpu = suite.play(TASK, "validation", controller)
        returns[label] = (played, cpu)
        rows += [{"controller": label, "context": index, "return": float(value)}
                 for index, value in enumerate(played)]  # fmt: skip
    with open(out / "validation-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    before = returns["before: the constructor's defaults"][0]
    print("| controller | mean return | − before [95% CI] | better / worse | CPU s |")
    print("|---|---:|---|---|---:|")
    for label, (played, cpu) in returns.items():
        print(f"| {label} | {played.mean():.3f} | {paired_difference_cells(played - before)} "
              f"| {cpu:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]))
