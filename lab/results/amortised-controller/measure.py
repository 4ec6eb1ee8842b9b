"""Measure the controller on the amortised belief (issue 61, item 2), on one thread.

    python lab/results/amortised-controller/measure.py sweep --belief belief.pt \
        --out docs/results/amortised-controller/validation-sweep.csv
    python lab/results/amortised-controller/measure.py paired \
        --new docs/results/amortised-controller/test-per-network.csv \
        --out docs/results/amortised-controller/paired.csv
    python lab/results/amortised-controller/measure.py timing --belief belief.pt \
        --out docs/results/amortised-controller/timing.csv
    python lab/results/amortised-controller/measure.py truth \
        --out docs/results/amortised-controller/told-the-column.csv

``sweep``: the settings tried, on the suite's validation sets (n16, n32). ``paired``:
network-by-network differences against identify-and-plan's committed test rows
(docs/results/suite/identify-and-plan-per-network.csv). ``timing``: decisions timed by
the real-time rig (``spikectl realtime`` at 1 kHz, wall clock from the frame's tick; a
decision over 1 ms is a miss) and each decision's CPU time on its thread
(``time.thread_time_ns``), on the generated test set of each size. ``truth``: the same
decision rule told each network's target column (no identification left to do).
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

REFERENCE = Path("docs/results/suite/identify-and-plan-per-network.csv")
SETTINGS = (
    ("greedy", 0.0), ("greedy", 0.5), ("greedy", 0.8), ("greedy", 0.95), ("thompson", 0.8),
)  # fmt: skip
"""(rule, probe_below) tried on validation: probe_below 0 never probes on quiet stretches."""


def write(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    print(f"wrote {path}")


def sweep(belief: Path, out: Path) -> None:
    from spikectl.agents.amortised_controller import AmortisedController, load_belief
    from spikectl.agents.amortised_kernel import BeliefKernel
    from spikectl.experiments import suite

    kernel = BeliefKernel(load_belief(belief))
    rows = []
    for rule, probe_below in SETTINGS:
        for task in ("n16", "n32"):
            started = time.process_time()
            returns, _ = suite.play(task, "validation", AmortisedController(
                kernel, rule=rule, probe_below=probe_below))  # fmt: skip
            rows.append({"task": task, "split": "validation", "rule": rule,
                         "probe_below": probe_below, "mean_return": f"{returns.mean():.6f}",
                         "cpu_seconds": f"{time.process_time() - started:.2f}"})  # fmt: skip
            print(rows[-1])
    write(rows, out)


def per_network(path: Path) -> dict[str, dict[int, float]]:
    table: dict[str, dict[int, float]] = defaultdict(dict)
    with open(path) as handle:
        for row in csv.DictReader(handle):
            table[row["task"]][int(row["context"])] = float(row["return"])
    return table


def paired(new: Path, out: Path) -> None:
    from spikectl.experiments.stats import bootstrap_ci

    ours, theirs = per_network(new), per_network(REFERENCE)
    rows = []
    for task, returns in ours.items():
        contexts = sorted(returns)
        difference = np.array([returns[c] - theirs[task][c] for c in contexts])
        interval = bootstrap_ci(difference, statistic=np.mean, n_resamples=10_000, rng=0)
        rows.append({
            "task": task, "networks": len(contexts),
            "amortised": f"{np.mean([returns[c] for c in contexts]):.6f}",
            "identify_and_plan": f"{np.mean([theirs[task][c] for c in contexts]):.6f}",
            "difference": f"{interval.estimate:.6f}", "low": f"{interval.low:.6f}",
            "high": f"{interval.high:.6f}", "better": int((difference > 1e-12).sum()),
            "worse": int((difference < -1e-12).sum()),
        })  # fmt: skip
        print(rows[-1])
    write(rows, out)


def rig(belief: Path, n: int, episodes: int) -> np.ndarray:
    """Every decision's latency (ms) from ``spikectl realtime`` (1 kHz, its generated
    test set of ``n`` neurons), read back from its --out file."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "decisions.csv"
        subprocess.run([sys.executable, "-m", "spikectl.cli", "realtime", str(belief),
                        "--n-neurons", str(n), "--episodes", str(episodes), "--out", str(out)],
                       check=True, stdout=subprocess.DEVNULL)  # fmt: skip
        with open(out) as handle:
            return np.array([float(row["latency_ms"]) for row in csv.DictReader(handle)])


def timing(belief: Path, out: Path, sizes: list[int], episodes: int) -> None:
    from spikectl import NeuronControlEnv, load_controller, make_splits

    rows = []
    for n in sizes:
        latencies = rig(belief, n, episodes)
        test_set = make_splits(100, 100, n, 60, seed=0, n_val=100)[1]  # the rig's set
        env = NeuronControlEnv(contexts=test_set)
        controller = load_controller(belief, env=env)
        cpu = []  # the same decisions, each one's CPU time on this thread
        for context in [0, *range(episodes)]:  # the first: an untimed warm-up, as the rig's
            controller.reset()
            observation, info = env.reset(seed=context, options={"context": context})
            for _ in range(env.episode_length):
                started = time.thread_time_ns()
                action = controller.act(observation, info)
                cpu.append((time.thread_time_ns() - started) / 1e6)
                observation, _, _, _, info = env.step(action)
        cpu = cpu[env.episode_length :]
        rows.append({
            "n_neurons": n, "episodes": episodes, "decisions": latencies.size,
            "rig_p50_ms": f"{np.percentile(latencies, 50):.4f}",
            "rig_p99_ms": f"{np.percentile(latencies, 99):.4f}",
            "rig_max_ms": f"{latencies.max():.4f}", "misses": int((latencies > 1.0).sum()),
            "cpu_p50_ms": f"{np.percentile(cpu, 50):.4f}",
            "cpu_p99_ms": f"{np.percentile(cpu, 99):.4f}",
            "load_average_1min": f"{os.getloadavg()[0]:.2f}",
        })  # fmt: skip
        print(rows[-1])
    write(rows, out)


class TrueColumns:
    """A belief certain of each played network's target column (the truth, read from
    ``info["context_index"]``-free order: the suite plays context i in sub-environment
    i, so copy i of the controller is told context i's column)."""

    def __init__(self, contexts, index: int = 0) -> None:
        self.contexts, self.index = contexts, index

    def reset(self, prior: np.ndarray) -> None:
        context = self.contexts[self.index]
        column = np.asarray(context.weights)[:, context.target]
        self.classes = np.where(column > 0, 1, np.where(column < 0, 2, 0))

    def step(self, features: np.ndarray) -> np.ndarray:
        logits = np.full((self.classes.size, 3), -30.0, dtype=np.float32)
        logits[np.arange(self.classes.size), self.classes] = 0.0
        return logits


def truth(out: Path) -> None:
    """The same decision rule told each network's target column: what identification
    alone could still add (the rest needs more than the column: cascades)."""
    from spikectl.agents.amortised_controller import AmortisedController
    from spikectl.experiments import suite

    class Told(AmortisedController):
        def spawn(self, index: int) -> AmortisedController:
            return Told(TrueColumns(self.kernel.contexts, index), self.params)

    rows = []
    for task in ("paper", "n16", "n32"):
        for split in ("validation", "test"):
            contexts = suite.load_split(task, split)
            returns, seconds = suite.play(task, split, Told(TrueColumns(contexts)))
            rows.append({"task": task, "split": split, "controller": "told the column",
                         "mean_return": f"{returns.mean():.6f}",
                         "cpu_seconds": f"{seconds:.2f}"})  # fmt: skip
            print(rows[-1])
    write(rows, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("sweep", "paired", "timing", "truth"))
    parser.add_argument("--belief", type=Path, default=Path("belief.pt"))
    parser.add_argument("--new", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument("--episodes", type=int, default=100)
    arguments = parser.parse_args()
    if arguments.what == "sweep":
        sweep(arguments.belief, arguments.out)
    elif arguments.what == "truth":
        truth(arguments.out)
    elif arguments.what == "paired":
        paired(arguments.new, arguments.out)
    else:
        timing(arguments.belief, arguments.out, arguments.sizes, arguments.episodes)


if __name__ == "__main__":
    main()
