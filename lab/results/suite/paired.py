"""Learned against planned, network by network: is a trained TDRQN (seeds 0-2) above
identify-and-plan on a task beyond the networks' sampling noise?

    python lab/results/suite/paired.py [TASK ...]       # needs runs/suite/guided/paper
    python lab/results/suite/paired.py --trained-on-task stochastic noise2 hidden25
    python lab/results/suite/paired.py --connectivity [TASK ...]  # runs/suite/guided-conn/paper
    python lab/results/suite/paired.py --preset guided-upr24 [--trained-on-task] [TASK ...]

For each task it plays identify-and-plan and each seed's best_model.pt on the task's 100
test networks under the suite's protocol, takes the per-network difference (the seeds'
mean return minus the planner's), and gives its mean with a 95% bootstrap interval over
the networks (10 000 resamples, seed 0). The seeds are those of runs/suite/PRESET/paper
(trained on `paper`, played on the task), or with --trained-on-task those of
runs/suite/PRESET/TASK (trained on the task itself). PRESET is `guided` by default
(paired.csv beside this file; the guided preset of docs/results/guided-floor20) and
`quick` with --trained-on-task (paired-trained-on-task.csv); --connectivity stands for
--preset guided-conn (links to runs/guided-conn01/seed=S; paired-guided-conn.csv); any
other preset writes paired-PRESET.csv or paired-PRESET-trained-on-task.csv. Rows of
tasks already in that CSV and not named this time are kept (in the suite's task order).
A seed whose committed folder (trained/PRESET/TASK-or-paper/seed=S) holds a
per_network.csv with the task's rows (`spikectl benchmark --per-network`, train.sh writes
it) is read from it, so its run need not exist; the others are played.
"""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path

import numpy as np

from spikectl.agents import GreedyController
from spikectl.envs import NeuronControlEnv
from spikectl.experiments import suite
from spikectl.training.loaders import load_agent, load_controller

# The committed data this script reads (its script lives in lab/results/, its data here).
HERE = Path(__file__).resolve().parents[3] / "docs" / "results" / "suite"
SEEDS = (0, 1, 2)
PER_NETWORK = "per_network.csv"


def output_name(preset: str, trained_on_task: bool) -> str:
    """The CSV beside this file for ``preset``'s seeds (the names of the first tables kept)."""
    known = {("guided", False): "paired.csv", ("quick", True): "paired-trained-on-task.csv",
             ("guided-conn", False): "paired-guided-conn.csv"}  # fmt: skip
    suffix = "-trained-on-task" if trained_on_task else ""
    return known.get((preset, trained_on_task), f"paired-{preset}{suffix}.csv")


def committed_returns(folder: Path, task: str) -> np.ndarray:
    """[100] a seed's test return on each network of ``task`` from its per_network.csv."""
    with open(folder / PER_NETWORK, newline="") as file:
        rows = [row for row in csv.DictReader(file) if row["task"] == task]
    size = suite.suite_version(1).set_size
    if [int(row["context"]) for row in rows] != list(range(size)):
        raise ValueError(f"{folder / PER_NETWORK} lacks the {size} networks of {task}")
    return np.array([float(row["return"]) for row in rows])


def seed_returns(preset: str, trained_on: str, seed: int, task: str) -> np.ndarray:
    """[100] seed ``seed`` of ``preset`` trained on ``trained_on``, on each test network
    of ``task``: from its committed per_network.csv, or played from its run."""
    kept = HERE / "trained" / preset / trained_on / f"seed={seed}"
    if (kept / PER_NETWORK).exists():
        return committed_returns(kept, task)
    run = Path(f"runs/suite/{preset}/{trained_on}/seed={seed}")
    network = load_agent(run, n_neurons=suite.task(task).n_observed, model="best")
    return suite.play(task, "test", GreedyController(network))[0]


def main(tasks: list[str], preset: str, trained_on_task: bool = False) -> None:
    rows = []
    for name in tasks:
        spec = suite.task(name)
        contexts = suite.load_split(name, "test")
        # The planner exactly as `spikectl benchmark identify-and-plan` builds it.
        env = NeuronControlEnv(contexts=contexts, extensions=spec.extensions)
        planner, _ = suite.play(name, "test", load_controller("identify-and-plan", env=env))
        trained_on = name if trained_on_task else "paper"
        learned = np.mean([seed_returns(preset, trained_on, seed, name) for seed in SEEDS],
                          axis=0)  # fmt: skip
        difference = learned - planner  # [100]
        resampled = np.random.default_rng(0).integers(0, difference.size, (10_000, difference.size))
        low, high = np.quantile(difference[resampled].mean(axis=1), [0.025, 0.975])
        rows.append({"task": name, "planner": f"{planner.mean():.4f}",
                     "learned": f"{learned.mean():.4f}", "difference": f"{difference.mean():.4f}",
                     "ci_low": f"{low:.4f}", "ci_high": f"{high:.4f}",
                     "networks_better": int((difference > 0).sum()),
                     "networks_worse": int((difference < 0).sum())})  # fmt: skip
        print(rows[-1])
    out = HERE / output_name(preset, trained_on_task)
    # The tasks not played this time keep their rows: a CSV grows task by task.
    kept = {}
    if out.exists():
        with open(out, newline="") as file:
            kept = {row["task"]: row for row in csv.DictReader(file)}
    kept.update({row["task"]: row for row in rows})
    ordered = [kept[name] for name in suite.suite_version(1).names() if name in kept]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(ordered)
    out.write_text(buffer.getvalue())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tasks", nargs="*", help="suite tasks (all by default)")
    parser.add_argument("--preset", help="the folder under runs/suite whose seeds to play")
    parser.add_argument("--trained-on-task", action="store_true",
                        help="the seeds trained on each task itself, not on `paper`")
    parser.add_argument("--connectivity", action="store_true",
                        help="the same as --preset guided-conn")
    arguments = parser.parse_args()
    if arguments.connectivity and arguments.preset not in (None, "guided-conn"):
        parser.error("--connectivity means --preset guided-conn; give one of them")
    default = "quick" if arguments.trained_on_task else "guided"
    preset = "guided-conn" if arguments.connectivity else arguments.preset or default
    main(arguments.tasks or list(suite.suite_version(1).names()), preset, arguments.trained_on_task)
