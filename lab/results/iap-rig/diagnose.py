"""Where identify-and-plan loses on suite v2's ``rig`` task: on the first NETWORKS
networks of the VALIDATION set (never the test set), network by network, the ``rig``
composition; the same told the true weights (the spike likelihood restricted to each
neuron's true input column: the potentials are still read from spikes alone, so what
is left is the loop's and the sensing's cost, not identification's); and both on the same
networks without the background input (what the spontaneous inputs cost).

    python lab/results/iap-rig/diagnose.py OUT_DIR [NETWORKS]

Writes OUT_DIR/diagnose-per-network.csv and prints the paired table.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import IdentifyAndPlan
from spikectl.planning.named import composition

TASK, SPLIT, VERSION = "rig", "validation", 2


class Told(IdentifyAndPlan):
    """The rig composition whose spike likelihood starts at the true columns (it reads
    the weights from the set by the environment's context index; a diagnostic)."""

    def __init__(self, contexts: ContextSet, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self._weights = contexts, None

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        if int(observation["step"]) == 0:
            self._weights = self.contexts[int(info["context_index"])].weights
        return super().act(observation, info)

    def _new_estimate(self, n: int):
        estimate = super()._new_estimate(n)
        estimate.keep_only(self._weights)
        return estimate


def subset(networks: int) -> ContextSet:
    full = suite.load_split(TASK, SPLIT, VERSION)
    return ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                      full.extensions)  # fmt: skip


def main(out: Path, networks: int) -> None:
    contexts = subset(networks)
    rig = suite.task(TASK, VERSION).extensions
    quiet = dataclasses.replace(rig, background_rate=0.0)
    named = composition("rig")
    runs = {
        "named": (rig, IdentifyAndPlan(composition=named, extensions=rig)),
        "told": (rig, Told(contexts, composition=named, extensions=rig)),
        "named-no-background": (quiet, IdentifyAndPlan(composition=named, extensions=quiet)),
        "told-no-background": (quiet, Told(contexts, composition=named, extensions=quiet)),
    }
    returns = {}
    with open(out / "diagnose-per-network.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["variant", "context", "return", "cpu_s"])
        for name, (extensions, controller) in runs.items():
            started = time.process_time()
            episodes = evaluate_policy(contexts, controller, extensions=extensions,
                                       seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
            cpu = time.process_time() - started
            returns[name] = np.asarray(episodes.returns)
            writer.writerows([name, i, f"{v:.6f}", f"{cpu / networks:.4f}"]
                             for i, v in enumerate(returns[name]))  # fmt: skip
            handle.flush()
            print(f"{name}: {returns[name].mean():.4f} ({cpu:.1f} CPU s)", flush=True)
    print("\n| variant | mean return | − named [95% CI] | better / worse |")
    print("|---|---:|---|---|")
    for name, values in returns.items():
        print(f"| {name} | {values.mean():.4f} | "
              f"{paired_difference_cells(values - returns['named'])} |")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 100)
