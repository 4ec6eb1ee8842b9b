"""Relays through hidden neurons (``IdentifyAndPlan(relays=True)``, the named controller
on ``hidden25`` now) against the controller before (``relays=False``), with other prior
variances of the relay weights and the other ideas tried, on the ``hidden25`` task's
train and validation sets (never the test set), network by network.

    python lab/results/hidden-relays/validation.py docs/results/hidden-relays

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
from spikectl.planning import ConnectivityEstimate, IdentifyAndPlan, RelayConnectivityEstimate

TASK = "hidden25"
SPLITS = ("train", "validation")


class RelayVariance(IdentifyAndPlan):
    """Relays with another prior variance of the relay weights; with ``plan=False``
    the relay weights are learned beside G but not planned with."""

    def __init__(self, variance: float, plan: bool = True, **settings) -> None:
        super().__init__(relays=True, **settings)
        self.variance, self.plan = variance, plan

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def _new_estimate(self, n: int):
        return RelayConnectivityEstimate(n, self._residual_sd, self.variance)

    def _compute_planning_weights(self):
        if self.plan:
            return super()._compute_planning_weights()
        return self._observed_planning_weights()

    def _planning_state(self):
        return super()._planning_state() if self.plan else self._tracker.state

    def _neurons(self):
        return super()._neurons() if self.plan else None


class ResidualNoise(IdentifyAndPlan):
    """No relays; the Gaussian estimate assumes residual noise ``sd`` (units of w_in)
    instead of the noise-free 0.01, so that one residual a hidden neuron moved is not
    decisive."""

    def __init__(self, sd: float, **settings) -> None:
        super().__init__(**settings)
        self.sd = sd

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def _new_estimate(self, n: int):
        return ConnectivityEstimate(n, self.sd)


def main(out: Path) -> None:
    variants = {
        "no relays (before)": IdentifyAndPlan(),
        "relays, prior variance 0.02 (now)": IdentifyAndPlan(relays=True),
        "relays, prior variance 0.01": RelayVariance(0.01),
        "relays, prior variance 0.03": RelayVariance(0.03),
        "relays, prior variance 0.05": RelayVariance(0.05),
        "relays, prior variance 0.1": RelayVariance(0.1),
        "relays, prior variance 0.2": RelayVariance(0.2),
        "relays learned (0.02), not planned": RelayVariance(0.02, plan=False),
        "relays learned (0.1), not planned": RelayVariance(0.1, plan=False),
        "no relays, residual noise 0.1": ResidualNoise(0.1),
        "no relays, residual noise 0.2": ResidualNoise(0.2),
        "no relays, residual noise 0.3, known_sd 0.35": ResidualNoise(0.3, known_sd=0.35),
    }  # fmt: skip
    rows, returns = [], {}
    for label, controller in variants.items():
        played, cpu = [], 0.0
        for split in SPLITS:
            values, seconds = suite.play(TASK, split, controller)
            played.append(values)
            cpu += seconds
            rows += [{"controller": label, "split": split, "context": index,
                      "return": float(value)} for index, value in enumerate(values)]  # fmt: skip
        returns[label] = (played, cpu)
    with open(out / "validation-per-network.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    before = returns["no relays (before)"][0]
    print("| controller | train | validation | − before, train + validation [95% CI] "
          "| better / worse | CPU s (200 episodes) |")  # fmt: skip
    print("|---|---:|---:|---|---|---:|")
    for label, (played, cpu) in returns.items():
        difference = np.concatenate(played) - np.concatenate(before)
        print(f"| {label} | {played[0].mean():.3f} | {played[1].mean():.3f} | "
              f"{paired_difference_cells(difference)} | {cpu:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]))
