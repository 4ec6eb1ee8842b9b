"""The named identify-and-plan on suite v2's ``rig`` TEST set, played once after the
choice on the validation set: the rows ``spikectl benchmark identify-and-plan --suite 2
--task rig --out ... --per-network ...`` writes, normalised against the do-nothing and
oracle rows already in docs/results/suite-v2 (the CLI would plan the oracle's 1 000
episodes again, ~1 200 CPU s, for the same numbers), and the paired differences against
the per-network returns there (doing nothing and the oracle on ``rig``, identify-and-plan
on ``spikes-only`` and ``chr2``).

    python lab/results/iap-rig/play_test_row.py OUT_DIR
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.named_row import play_named, write_rows
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells

TASK, SPLIT, VERSION = "rig", "test", 2
OLD = Path("docs/results/suite-v2")
COLUMNS = ["suite_version", "task", "split", "controller", "model", "seeds", "mean_return",
           "standard_error", "sd_over_seeds", "normalised", "do_nothing", "oracle",
           "cpu_seconds", "contexts", "trained_on", "composition"]  # fmt: skip


def reference(controller: str) -> float:
    with open(OLD / f"{controller}.csv") as handle:
        return float(next(r for r in csv.DictReader(handle) if r["task"] == TASK)["mean_return"])


def per_network(controller: str, task: str) -> np.ndarray:
    with open(OLD / f"{controller}-per-network.csv") as handle:
        rows = [r for r in csv.DictReader(handle) if r["task"] == task]
    return np.array([float(r["return"]) for r in sorted(rows, key=lambda r: int(r["context"]))])


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    result, composition, n_networks = play_named(TASK, SPLIT, VERSION)
    nothing, oracle = reference("do-nothing"), reference("oracle")
    row = dict(zip(COLUMNS, [
        VERSION, TASK, SPLIT, "identify-and-plan", "", 1, f"{result.mean_return:.6f}",
        f"{result.standard_error:.6f}", "",
        f"{suite.normalise(result.mean_return, nothing, oracle):.6f}", f"{nothing:.6f}",
        f"{oracle:.6f}", f"{result.cpu_seconds:.3f}", n_networks, "", composition,
    ], strict=True))  # fmt: skip
    write_rows(out, TASK, row, result, composition, VERSION)
    print(f"rig test: {result.mean_return:.4f} ± {result.standard_error:.4f} (normalised "
          f"{row['normalised']}); {result.cpu_seconds:.1f} CPU s; {composition}")  # fmt: skip
    for controller, task in (("do-nothing", "rig"), ("oracle", "rig"),
                             ("identify-and-plan", "spikes-only"),
                             ("identify-and-plan", "chr2")):  # fmt: skip
        other = per_network(controller, task)
        print(f"− {controller} on {task}, network by network: "
              f"{paired_difference_cells(result.returns - other)}")  # fmt: skip


if __name__ == "__main__":
    main(Path(sys.argv[1]))
