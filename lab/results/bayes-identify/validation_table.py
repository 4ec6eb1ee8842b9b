"""The validation table of docs/baselines.md (issue 43): normalised score per task and
setting from the validation sweeps, and each setting's paired difference from the old
default: mean over the 100 networks, 95% bootstrap interval (10 000 resamples, seed 0).
Settings that change nothing on a task are left out.

    python lab/results/bayes-identify/validation_table.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from spikectl.experiments import suite
from spikectl.experiments.stats import bootstrap_ci

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "bayes-identify"
SWEEPS = sorted(HERE.glob("validation-sweep[0-9].csv"))
NAMES = {
    "{}": "old default",
    '{"identification": "bayes", "extensions": true}': "Bayes model",
    '{"identification": "bayes", "extensions": true, "filter_voltage": true}':
        "Bayes model + filtered potentials",
    '{"extensions": true}': "Gaussian, told the extensions (release chances)",
    '{"filter_voltage": true}': "Gaussian + filtered potentials",
    '{"extensions": true, "gamble_networks": 16}':
        "Gaussian, told the extensions, + QMDP over 16 drawn networks",
    '{"identification": "bayes", "extensions": true, "filter_voltage": true, '
    '"gamble_networks": 16}': "Bayes model + filtered potentials + QMDP over 16 drawn networks",
}  # fmt: skip


def main() -> None:
    rows, returns = {}, {}
    for path in SWEEPS:
        for r in csv.DictReader(open(path)):
            rows[(r["task"], r["settings"])] = r
        for r in csv.DictReader(open(str(path).replace(".csv", "-per-network.csv"))):
            key = (r["task"], r["settings"])
            returns.setdefault(key, {})[int(r["context"])] = float(r["return"])
    print("| task | setting | normalised (return) | − old default [95% CI] | CPU s / episode |")
    print("|---|---|---|---|---|")
    order = list(suite.suite_version(1).names())
    for (task, settings), r in sorted(rows.items(), key=lambda item: order.index(item[0][0])):
        old = returns.get((task, "{}"))
        difference = "–"
        if settings != "{}" and old is not None:
            new = returns[(task, settings)]
            d = np.array([new[c] - old[c] for c in sorted(old)])
            if not d.any():
                continue  # the setting does nothing on this task (e.g. a filter without noise)
            i = bootstrap_ci(d, statistic=np.mean, n_resamples=10_000, rng=0)
            difference = f"{i.estimate:+.3f} [{i.low:+.3f}, {i.high:+.3f}]"
        print(
            f"| `{task}` | {NAMES.get(settings, settings)} | {float(r['normalised']):.3f} "
            f"({float(r['mean_return']):.3f}) | {difference} | {r['cpu_s_per_episode']} |"
        )


if __name__ == "__main__":
    main()
