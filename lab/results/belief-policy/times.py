"""Decision times of controllers from weights files, timed in one run as the
realtime-tradeoff record times its rows (its ``timed``: each decision's CPU time on its
thread, one environment, the first 10 test networks of suite v1's ``paper``, ``n16`` and
``n32`` and of the n = 64 set, after a warm-up episode).

    python lab/results/belief-policy/times.py OUT.csv NAME=FILE.pt [NAME=FILE.pt ...]

Rows: ``n_neurons, task, controller, decision_p50_ms, decision_p99_ms, load_average_1min``.
"""

from __future__ import annotations

import csv
import importlib.util
import os
import sys
from pathlib import Path

import torch

from spikectl import load_controller

_spec = importlib.util.spec_from_file_location(
    "tradeoff", Path(__file__).resolve().parents[1] / "realtime-tradeoff" / "measure.py")
tradeoff = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tradeoff)


def main() -> None:
    out, files = Path(sys.argv[1]), [entry.partition("=") for entry in sys.argv[2:]]
    torch.set_num_threads(1)
    rows = []
    for task in (*tradeoff.TASKS, "n64"):
        contexts, extensions = tradeoff.test_set(task)
        for name, _, path in files:
            controller = load_controller(path, contexts=contexts)
            p50, p99 = tradeoff.timed(contexts, extensions, controller)
            rows.append({"n_neurons": contexts.n_neurons, "task": task, "controller": name,
                         "decision_p50_ms": f"{p50:.4f}", "decision_p99_ms": f"{p99:.4f}",
                         "load_average_1min": f"{os.getloadavg()[0]:.2f}"})  # fmt: skip
            print(rows[-1], flush=True)
    with open(out, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
