"""Learned against planned, network by network: is the main job's TDRQN (guided, trained on
`paper`, seeds 0-2) above identify-and-plan on a task beyond the networks' sampling noise?

    python docs/results/suite/paired.py [TASK ...]       # needs runs/suite/guided/paper
    python docs/results/suite/paired.py --trained-on-task stochastic noise2 hidden25
    python docs/results/suite/paired.py --connectivity [TASK ...]  # runs/suite/guided-conn/paper

For each task it plays identify-and-plan and each seed's best_model.pt on the task's 100
test networks under the suite's protocol, takes the per-network difference (the seeds'
mean return minus the planner's), and gives its mean with a 95% bootstrap interval over
the networks (10 000 resamples, seed 0). The seeds are those of runs/suite/guided/paper
(paired.csv beside this file), or with --trained-on-task those of
runs/suite/quick/TASK (paired-trained-on-task.csv), or with --connectivity those of the
guided preset with the connectivity loss, runs/suite/guided-conn/paper (links to
runs/guided-conn01/seed=S; paired-guided-conn.csv).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from spikectl.agents.greedy import GreedyController
from spikectl.envs.env import NeuronControlEnv
from spikectl.experiments import suite
from spikectl.training.controllers import load_agent, load_controller

HERE = Path(__file__).resolve().parent
SEEDS = (0, 1, 2)


def main(tasks: list[str], trained_on_task: bool = False, connectivity: bool = False) -> None:
    rows = []
    for name in tasks:
        spec = suite.task(name)
        contexts = suite.load_split(name, "test")
        # The planner exactly as `spikectl benchmark identify-and-plan` builds it.
        env = NeuronControlEnv(contexts=contexts, params=contexts.params,
                               extensions=spec.extensions)  # fmt: skip
        planner, _ = suite.play(name, "test", load_controller("identify-and-plan", env=env))
        folder = (
            f"runs/suite/quick/{name}"
            if trained_on_task
            else f"runs/suite/{'guided-conn' if connectivity else 'guided'}/paper"
        )
        runs = [Path(f"{folder}/seed={seed}") for seed in SEEDS]
        learned = np.mean([
            suite.play(name, "test", GreedyController(
                load_agent(run, n_neurons=spec.n_observed, model="best")))[0]
            for run in runs
        ], axis=0)  # fmt: skip
        difference = learned - planner  # [100]
        resampled = np.random.default_rng(0).integers(0, difference.size, (10_000, difference.size))
        low, high = np.quantile(difference[resampled].mean(axis=1), [0.025, 0.975])
        rows.append({"task": name, "planner": f"{planner.mean():.4f}",
                     "learned": f"{learned.mean():.4f}", "difference": f"{difference.mean():.4f}",
                     "ci_low": f"{low:.4f}", "ci_high": f"{high:.4f}",
                     "networks_better": int((difference > 0).sum()),
                     "networks_worse": int((difference < 0).sum())})  # fmt: skip
        print(rows[-1])
    out = HERE / (
        "paired-trained-on-task.csv"
        if trained_on_task
        else "paired-guided-conn.csv"
        if connectivity
        else "paired.csv"
    )
    with open(out, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    arguments = sys.argv[1:]
    flags = {"--trained-on-task", "--connectivity"}
    tasks = [a for a in arguments if a not in flags]
    main(
        tasks or list(suite.TASKS), "--trained-on-task" in arguments, "--connectivity" in arguments
    )
