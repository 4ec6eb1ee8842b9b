"""The threshold identify-and-plan plans with under measurement noise, on the noise tasks'
train and validation sets (never the test sets), network by network: the paper's
threshold (before), the filter's read margin, spike_margin_sd x the noise (the named
controller now: 2, 4 and 8 mV at 1, 2 and 4 mV of noise), and fixed margins.

    python lab/results/filter-margin/validation.py docs/results/filter-margin

Writes ``validation-per-network.csv`` and prints the table of ``validation-table.txt``.
"""

from __future__ import annotations

import copy
import csv
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.neuron.simulator import neuron_parameters
from spikectl.planning.filtering import FilteredState
from spikectl.planning.policy import IdentifyAndPlan, environment_settings

TASKS = ("noise1", "noise2", "noise4")
SPLITS = ("train", "validation")
FIXED_MARGINS_MV = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0)


class Margin(IdentifyAndPlan):
    """The named controller planning from the filtered potentials with the threshold
    ``margin_mV`` below the paper's (None: the paper's neurons, as before)."""

    def __init__(self, margin_mV: float | None, **settings) -> None:
        super().__init__(**settings)
        self.margin_mV = margin_mV
        self._margin_neurons: np.ndarray | None = None

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def _neurons(self):
        if not isinstance(self._tracker, FilteredState):
            return super()._neurons()
        if self.margin_mV is None:
            return None
        n = self._tracker.state.voltage_mV.shape[-1]
        if self._margin_neurons is None or self._margin_neurons.shape[-1] != n:
            self._margin_neurons = neuron_parameters(
                self.params, np.full((1, n), self.params.v_threshold_mV - self.margin_mV),
                np.full((1, n), self.params.membrane_time_constant_ms))  # fmt: skip
        return self._margin_neurons


def main(out: Path) -> None:
    rows, lines = [], []
    for task in TASKS:
        extensions = suite.task(task).extensions
        settings = {"noise_mV": extensions.observation_noise_mV,
                    **environment_settings(extensions, 8)}  # fmt: skip
        variants = {"the paper's threshold (before)": Margin(None, **settings),
                    "the read margin (now)": IdentifyAndPlan(**settings),
                    **{f"{margin:g} mV below": Margin(margin, **settings)
                       for margin in FIXED_MARGINS_MV}}  # fmt: skip
        returns = {}
        for label, controller in variants.items():
            played, cpu = [], 0.0
            for split in SPLITS:
                values, seconds = suite.play(task, split, controller)
                played.append(values)
                cpu += seconds
                rows += [{"task": task, "controller": label, "split": split,
                          "context": index, "return": float(value)}
                         for index, value in enumerate(values)]  # fmt: skip
            returns[label] = (np.concatenate(played), cpu)
        before = returns["the paper's threshold (before)"][0]
        for label, (played, cpu) in returns.items():
            lines.append(f"| `{task}` | {label} | {played.mean():.3f} | "
                         f"{paired_difference_cells(played - before)} | {cpu:.1f} |")  # fmt: skip
    with open(out / "validation-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print("Train + validation (200 networks a task), network by network:\n")
    print("| task | planned threshold | mean return | − before [95% CI] | better / worse | CPU s |")
    print("|---|---|---:|---|---|---:|")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
