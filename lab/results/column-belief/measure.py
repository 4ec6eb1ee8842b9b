"""Is the amortised controller held back by its belief or by its one-column rule (issue
61)? The same controller (``AmortisedController``: its greedy rule on P(G[i, target] =
+1), its probes on quiet stretches) fed identify-and-plan's exact Gaussian posterior of
the target's column in place of the trained belief: no training, and one n x n solve a
step with a release.

    python lab/results/column-belief/measure.py validation OUT_DIR   # + the named planner
    python lab/results/column-belief/measure.py test OUT_DIR
    python lab/results/column-belief/measure.py times OUT_DIR
    python lab/results/column-belief/measure.py table OUT_DIR        # README's tables

``validation``: the column controller and the named identify-and-plan on suite v1's
``paper``, ``n16`` and ``n32`` validation sets (100 networks each), each network's
return kept. ``test``: the column controller on the same tasks' test sets, each network's
return kept; ``table`` sets it against the committed per-network rows of the named
identify-and-plan (docs/results/suite) and of the amortised controller
(docs/results/amortised-controller). ``times``: each decision's CPU time on its thread,
the set's first 10 test networks after a warm-up episode, one thread, as
lab/results/realtime-tradeoff times a row.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.column import GaussianColumn
from lab.records import write_csv
from spikectl import NeuronControlEnv, load_controller
from spikectl.agents.amortised_controller import AmortisedController
from spikectl.envs.realtime import decision_times
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells

ROOT = Path(__file__).resolve().parents[3]
RESULTS = ROOT / "docs" / "results"
TASKS = ("paper", "n16", "n32")
TIMED_EPISODES = 10


def column_controller(params) -> AmortisedController:
    return AmortisedController(GaussianColumn(), params)


def rows_of(task, split, name, returns, cpu):
    summary = {"task": task, "split": split, "controller": name,
               "mean_return": f"{returns.mean():.6f}",
               "standard_error": f"{suite.standard_error(returns):.6f}",
               "cpu_seconds": f"{cpu:.1f}"}  # fmt: skip
    per_network = [{"task": task, "split": split, "controller": name, "context": i,
                    "return": repr(float(value))} for i, value in enumerate(returns)]  # fmt: skip
    return summary, per_network


def measure(out: Path, split: str, with_named: bool) -> None:
    summaries, per_network = [], []
    for task in TASKS:
        contexts = suite.load_split(task, split)
        controllers = {"column controller": column_controller(contexts.params)}
        if with_named:
            env = NeuronControlEnv(contexts=contexts, extensions=suite.task(task).extensions)
            controllers["identify-and-plan"] = load_controller("identify-and-plan", env=env)
        for name, controller in controllers.items():
            returns, cpu = suite.play(task, split, controller, version=1)
            returns = np.asarray(returns)
            summary, rows = rows_of(task, split, name, returns, cpu)
            summaries.append(summary)
            per_network += rows
            print(summary, flush=True)
    write_csv(out / f"{split}.csv", summaries)
    write_csv(out / f"{split}-per-network.csv", per_network)


def times(out: Path) -> None:
    rows = []
    for task in TASKS:
        contexts = suite.load_split(task, "test")
        env = NeuronControlEnv(contexts=contexts, extensions=suite.task(task).extensions)
        controller = column_controller(contexts.params)
        decision_times(env, controller, [0])
        taken = decision_times(env, controller, range(TIMED_EPISODES)) * 1e3
        rows.append({"task": task, "n_neurons": contexts.n_neurons,
                     "decision_p50_ms": f"{np.median(taken):.4f}",
                     "decision_p99_ms": f"{np.percentile(taken, 99):.4f}"})  # fmt: skip
        print(rows[-1], flush=True)
    write_csv(out / "times.csv", rows)


def read_csv(path: Path) -> list[dict]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def returns_of(rows, task, split, controller=None) -> np.ndarray:
    chosen = sorted((r for r in rows if r["task"] == task and r["split"] == split
                     and (controller is None or r["controller"] == controller)),
                    key=lambda r: int(r["context"]))  # fmt: skip
    return np.array([float(r["return"]) for r in chosen])


def table(out: Path) -> str:
    validation = read_csv(out / "validation-per-network.csv")
    test = read_csv(out / "test-per-network.csv")
    named = read_csv(RESULTS / "suite" / "identify-and-plan-per-network.csv")
    amortised = read_csv(RESULTS / "amortised-controller" / "test-per-network.csv")
    lines = ["| task | split | column controller | identify-and-plan (named) | "
             "column − named, per network [95%] | better / worse |",
             "|---|---|---:|---:|---|---|"]  # fmt: skip
    for split, rows, reference in (("validation", validation, validation), ("test", test, named)):
        for task in TASKS:
            mine = returns_of(rows, task, split, "column controller")
            theirs = returns_of(reference, task, split,
                                "identify-and-plan")  # fmt: skip
            lines.append(f"| `{task}` | {split} | {mine.mean():.3f} | {theirs.mean():.3f} | "
                         f"{paired_difference_cells(mine - theirs)} |")  # fmt: skip
    lines += ["", "| task | column controller | amortised controller | column − amortised, "
              "per network [95%] | better / worse |", "|---|---:|---:|---|---|"]  # fmt: skip
    for task in TASKS:
        mine = returns_of(test, task, "test")
        theirs = returns_of(amortised, task, "test")
        lines.append(f"| `{task}` | {mine.mean():.3f} | {theirs.mean():.3f} | "
                     f"{paired_difference_cells(mine - theirs)} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("validation", "test", "times", "table"))
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    {"validation": lambda: measure(args.out, "validation", with_named=True),
     "test": lambda: measure(args.out, "test", with_named=False),
     "times": lambda: times(args.out),
     "table": lambda: print(table(args.out))}[args.what]()  # fmt: skip


if __name__ == "__main__":
    main()
