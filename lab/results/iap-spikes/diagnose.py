"""Where identify-and-plan loses on suite v2's ``spikes-only`` task: on the first
NETWORKS networks of the VALIDATION set (never the test set), network by network, the
``spikes`` composition without QMDP (``spikes-fast``, the named one before this record)
against the same loop told the true input columns, every neuron's or the target's alone.
Told, the filter is the spike likelihood (without background input it is the exact
filter: the same columns and potentials, step by step) restricted to the true columns
(:meth:`~spikectl.planning.spike_likelihood.SpikeLikelihoodFilter.keep_only`): the
potentials are still read from spikes, so what is left is the loop's cost, and the
difference is identification's.

    python lab/results/iap-spikes/diagnose.py OUT_DIR [NETWORKS]

Writes OUT_DIR/diagnose-per-network.csv and prints the paired table.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.screen import diagnose, subset
from lab.planners.told import ToldColumns
from spikectl.experiments import suite
from spikectl.planning import EstimatorSettings, IdentifyAndPlan, ObservationSettings
from spikectl.planning.named import composition

TASK, VERSION = "spikes-only", 2


def main(out: Path, networks: int) -> None:
    contexts = subset(TASK, range(networks))
    extensions = suite.task(TASK, VERSION).extensions
    before = composition("spikes-fast")
    told = before.but("told", estimator=EstimatorSettings("spike-likelihood"),
                      observation=ObservationSettings(task_model=True))  # fmt: skip
    runs = {
        "no-qmdp": (extensions, IdentifyAndPlan(composition=before, extensions=extensions)),
        "told-all-columns": (extensions, ToldColumns(contexts, "all", composition=told,
                                                     extensions=extensions)),
        "told-target-column": (extensions, ToldColumns(contexts, "target", composition=told,
                                                       extensions=extensions)),
    }  # fmt: skip
    diagnose(out / "diagnose-per-network.csv", contexts, runs, "no-qmdp")


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 100)
