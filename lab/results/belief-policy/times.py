"""Decision times of controllers from weights files, timed in one run as the
realtime-tradeoff record times its rows: each decision's CPU time on its thread
(``spikectl.envs.realtime.decision_times``), one environment, the first 10 test
networks of suite v1's ``paper``, ``n16`` and ``n32`` and of the n = 64 set, after a
warm-up episode.

    python lab/results/belief-policy/times.py OUT.csv NAME=FILE.pt [NAME=FILE.pt ...]

Rows: ``n_neurons, task, controller, decision_p50_ms, decision_p99_ms, load_average_1min``.
"""

from __future__ import annotations

import csv
import os
import sys
from pathlib import Path

import numpy as np
import torch

from spikectl import NeuronControlEnv, load_controller, make_splits
from spikectl.envs.realtime import decision_times
from spikectl.experiments import suite

TIMED_EPISODES = 10


def main() -> None:
    out, files = Path(sys.argv[1]), [entry.partition("=") for entry in sys.argv[2:]]
    torch.set_num_threads(1)
    rows = []
    for task in ("paper", "n16", "n32", "n64"):
        if task == "n64":
            contexts, extensions = make_splits(100, 100, 64, seed=0, n_val=100)[1], None
        else:
            contexts, extensions = suite.load_split(task, "test", 1), suite.task(task, 1).extensions
        env = NeuronControlEnv(contexts=contexts, extensions=extensions)
        for name, _, path in files:
            controller = load_controller(path, env=env)
            decision_times(env, controller, [0])  # warm-up: compilation, caches
            times = decision_times(env, controller, range(TIMED_EPISODES)) * 1e3
            rows.append({"n_neurons": contexts.n_neurons, "task": task, "controller": name,
                         "decision_p50_ms": f"{np.median(times):.4f}",
                         "decision_p99_ms": f"{np.percentile(times, 99):.4f}",
                         "load_average_1min": f"{os.getloadavg()[0]:.2f}"})  # fmt: skip
            print(rows[-1], flush=True)
    with open(out, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
