"""A column that did not move while several neurons released together, counted as no
synapse from each of them (``ConfoundedZeros`` below), against the named controller, on
the ``n16`` train and validation sets and the first 70
``n32`` validation networks (never the test sets), network by network; and on the
``paper`` train and validation sets, where it is not taken.

    python docs/results/confounded-zeros/validation.py docs/results/confounded-zeros TASK

Writes ``validation-TASK-per-network.csv`` and prints the table of
``validation-TASK.txt``.
"""

from __future__ import annotations

import csv
import sys
import time
from pathlib import Path

import numpy as np

from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning.identify import ConnectivityEstimate
from spikectl.planning.policy import IdentifyAndPlan, environment_settings

SETS = {"paper": {"train": 100, "validation": 100}, "n16": {"train": 100, "validation": 100},
        "n32": {"validation": 70}}  # fmt: skip
"""The networks each task plays: the first N of each set (n32's episodes cost ~12 CPU s)."""
ZERO_SDS = {"paper": (0.2, 0.1), "n16": (0.2, 0.1, 0.3), "n32": (0.2,)}


class ZeroSumEstimate(ConnectivityEstimate):
    """The Gaussian estimate, and where two or more neurons surely released (1, not a
    release chance) and an observed column's residual rounds to 0, one observation of 0
    with standard deviation ``zero_sd`` of each of their synapses onto it: the Gaussian
    knows only their sum, but under the generator's sparse prior a sum of 0 is nearly
    always no synapse at all (an excitatory and an inhibitory one cancelling is about 17
    times rarer for two neighbours)."""

    def __init__(self, n_neurons: int, residual_sd: float, zero_sd: float) -> None:
        super().__init__(n_neurons, residual_sd)
        self._zero_precision = zero_sd**-2

    def add(self, released: np.ndarray, residual: np.ndarray, observed: np.ndarray) -> None:
        super().add(released, residual, observed)
        if not observed.any() or ((released > 0) & (released < 1)).any():
            return
        releasers = np.flatnonzero(released == 1)
        if releasers.shape[0] < 2:
            return
        still = np.flatnonzero(observed & (np.abs(residual) < 0.5))  # [columns]
        self.precision[still[:, None], releasers, releasers] += self._zero_precision
        self.version += 1
        self._cache = self._parts = None
        self._weights.clear()


class ConfoundedZeros(IdentifyAndPlan):
    """The named controller with :class:`ZeroSumEstimate`."""

    def __init__(self, zero_sd: float, **settings) -> None:
        super().__init__(**settings)
        self.zero_sd = zero_sd

    def spawn(self, index: int) -> IdentifyAndPlan:
        copied = super().spawn(index)
        copied.__class__, copied.zero_sd = ConfoundedZeros, self.zero_sd
        return copied

    def _new_estimate(self, n: int):
        return ZeroSumEstimate(n, self._residual_sd, self.zero_sd)


def main(out: Path, task: str) -> None:
    spec = suite.task(task)
    settings = environment_settings(spec.extensions, spec.n_neurons)
    variants = {"named controller": IdentifyAndPlan(**settings)}
    for zero_sd in ZERO_SDS[task]:
        variants[f"confounded zeros, sd {zero_sd}"] = ConfoundedZeros(zero_sd, **settings)
    rows, returns = [], {}
    for label, controller in variants.items():
        played, started = [], time.process_time()
        for split, size in SETS[task].items():
            contexts = suite.load_split(task, split)[:size]
            values = evaluate_policy(
                contexts, controller, extensions=spec.extensions,
                seed=suite.suite_version(1).env_seed,
            ).returns
            played.append(values)
            rows += [{"controller": label, "split": split, "context": index,
                      "return": float(value)} for index, value in enumerate(values)]  # fmt: skip
        returns[label] = (played, time.process_time() - started)
        print(f"# {label} done", file=sys.stderr, flush=True)
    with open(out / f"validation-{task}-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    before = returns["named controller"][0]
    splits = " | ".join(f"{split} ({size})" for split, size in SETS[task].items())
    print(f"| `{task}` | {splits} | − named [95% CI] | better / worse | CPU s |")
    print("|---|" + "---:|" * len(SETS[task]) + "---|---|---:|")
    for label, (played, cpu) in returns.items():
        difference = np.concatenate(played) - np.concatenate(before)
        means = " | ".join(f"{values.mean():.3f}" for values in played)
        print(f"| {label} | {means} | {paired_difference_cells(difference)} | {cpu:.0f} |")


if __name__ == "__main__":
    main(Path(sys.argv[1]), sys.argv[2])
