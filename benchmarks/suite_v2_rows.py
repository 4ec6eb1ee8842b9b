"""Suite v2's rows for some tasks, every controller in one process, so the oracle's
reference (what each row is normalised against) is planned once, not once a controller:

    python benchmarks/suite_v2_rows.py chr2 --out-dir docs/results/suite-v2/new

writes CONTROLLER-TASKS.csv and CONTROLLER-TASKS-per-network.csv for the oracle, do
nothing, random and identify-and-plan (``--controllers`` chooses some), exactly as
``spikectl benchmark CONTROLLER --suite 2 --task TASKS --out ... --per-network ...``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from spikectl.cli import main

CONTROLLERS = ("oracle", "do-nothing", "random", "identify-and-plan")

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tasks", nargs="+")
    parser.add_argument("--out-dir", type=Path, required=True)
    parser.add_argument("--controllers", nargs="+", default=CONTROLLERS, choices=CONTROLLERS)
    args = parser.parse_args()
    args.out_dir.mkdir(parents=True, exist_ok=True)
    label = "-".join(args.tasks)
    for controller in args.controllers:
        stem = args.out_dir / f"{controller}-{label}"
        outputs = ["--out", f"{stem}.csv", "--per-network", f"{stem}-per-network.csv"]
        main(["benchmark", controller, "--suite", "2", "--task", *args.tasks, *outputs])
