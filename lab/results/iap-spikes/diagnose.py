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

import copy
import csv
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.screen import subset
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import EstimatorSettings, IdentifyAndPlan, ObservationSettings
from spikectl.planning.named import composition

TASK, VERSION = "spikes-only", 2


class Told(IdentifyAndPlan):
    """The loop whose spike likelihood starts at the true columns of ``columns``
    ("all", or "target": the episode's target alone), read from the set by the
    environment's context index (a diagnostic)."""

    def __init__(self, contexts, columns: str, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self.columns = contexts, columns
        self._weights, self._target = None, None

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        if int(observation["step"]) == 0:
            self._weights = self.contexts[int(info["context_index"])].weights
            self._target = int(observation["target"])
        return super().act(observation, info)

    def _new_estimate(self, n: int):
        estimate = super()._new_estimate(n)
        estimate.keep_only(self._weights, None if self.columns == "all" else [self._target])
        return estimate


def main(out: Path, networks: int) -> None:
    contexts = subset(TASK, range(networks))
    extensions = suite.task(TASK, VERSION).extensions
    before = composition("spikes-fast")
    told = before.but("told", estimator=EstimatorSettings("spike-likelihood"),
                      observation=ObservationSettings(task_model=True))  # fmt: skip
    runs = {
        "no-qmdp": IdentifyAndPlan(composition=before, extensions=extensions),
        "told-all-columns": Told(contexts, "all", composition=told, extensions=extensions),
        "told-target-column": Told(contexts, "target", composition=told, extensions=extensions),
    }
    returns = {}
    with open(out / "diagnose-per-network.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["variant", "context", "return", "cpu_s"])
        for name, controller in runs.items():
            started = time.process_time()
            episodes = evaluate_policy(contexts, controller, extensions=extensions,
                                       seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
            cpu = time.process_time() - started
            returns[name] = np.asarray(episodes.returns)
            writer.writerows([name, i, f"{v:.6f}", f"{cpu / networks:.4f}"]
                             for i, v in enumerate(returns[name]))  # fmt: skip
            handle.flush()
            print(f"{name}: {returns[name].mean():.4f} ({cpu:.1f} CPU s)", flush=True)
    print("\n| variant | mean return | − no-qmdp [95% CI] | better / worse |")
    print("|---|---:|---|---|")
    for name, values in returns.items():
        print(f"| {name} | {values.mean():.4f} | "
              f"{paired_difference_cells(values - returns['no-qmdp'])} |")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 100)
