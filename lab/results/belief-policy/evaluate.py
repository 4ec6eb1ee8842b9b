"""Play controllers from weights files on suite v1 tasks, one thread, and append one row
per network to a CSV.

    python lab/results/belief-policy/evaluate.py OUT.csv --split validation \
        --tasks paper n16 n32 --files NAME=FILE.pt [NAME=FILE.pt ...]

``n64`` is the realtime-tradeoff record's test set at n = 64 (suite v1's rule at that
size), played under the suite's protocol (that record's ``played``). A belief policy's
file plays the belief policy, a belief's file the amortised controller (its fixed rule),
as ``spikectl.load_controller`` reads them. Rows: ``controller, task, split, context,
return, cpu_s`` (cpu_s: the whole set's process CPU seconds, on each row). Prints each
controller's mean per task.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
from pathlib import Path

import numpy as np
import torch

from spikectl import load_controller
from spikectl.experiments import suite

_spec = importlib.util.spec_from_file_location(
    "tradeoff", Path(__file__).resolve().parents[1] / "realtime-tradeoff" / "measure.py")
tradeoff = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tradeoff)


def play(task: str, split: str, path: str) -> tuple[np.ndarray, float]:
    """(returns [S], CPU seconds) of the controller in ``path`` on a task's split."""
    if task == "n64":
        if split != "test":
            raise SystemExit("n64 has a test set only (realtime-tradeoff's)")
        contexts, extensions = tradeoff.test_set(task)
    else:
        contexts, extensions = suite.load_split(task, split, 1), suite.task(task, 1).extensions
    return tradeoff.played(contexts, extensions, load_controller(path, contexts=contexts))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--split", default="validation", choices=("validation", "test"))
    parser.add_argument("--tasks", nargs="+", default=["paper", "n16", "n32"])
    parser.add_argument("--files", nargs="+", required=True, help="NAME=FILE")
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    new = not arguments.out.exists()
    with open(arguments.out, "a", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        if new:
            writer.writerow(["controller", "task", "split", "context", "return", "cpu_s"])
        for entry in arguments.files:
            name, _, path = entry.partition("=")
            for task in arguments.tasks:
                returns, seconds = play(task, arguments.split, path)
                for context, value in enumerate(returns):
                    writer.writerow([name, task, arguments.split, context, f"{value:.6f}",
                                     f"{seconds:.2f}"])  # fmt: skip
                handle.flush()
                print(f"{name} {task} {arguments.split}: {returns.mean():.4f} "
                      f"({seconds:.0f} CPU s)", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
