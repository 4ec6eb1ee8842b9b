"""Identify-and-plan under loop latency (docs/extensions.md, "Loop latency"): mean returns
on the paper task's 100 unseen test networks for latency_steps 0, 1, 2 (or --latencies).

Rows: doing nothing; the latency-aware oracle (``OraclePlanner``, which knows the network);
identify-and-plan (the named controller, which reads the latency from the observation's
actions in flight, reads each step's evidence with the action that landed then and plans
from the state its action will meet). Each value is the mean ± its standard error over
the networks; the CPU seconds are identify-and-plan's over the 100 episodes. Seconds:

    python benchmarks/latency_identify_and_plan.py
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.envs.controller import DoNothing
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.planning.named import named_composition
from spikectl.planning.oracle import OraclePlanner
from spikectl.planning.policy import IdentifyAndPlan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--latencies", type=int, nargs="+", default=[0, 1, 2])
    arguments = parser.parse_args()
    contexts = load_split("paper", "test")
    n = contexts[0].n_neurons
    oracle = OraclePlanner(contexts, contexts.params)
    print("| latency | do nothing | latency-aware oracle | identify-and-plan | its CPU s |")
    print("|---:|---:|---:|---:|---:|")
    for latency in arguments.latencies:
        extensions = Extensions(latency_steps=latency)
        planner = IdentifyAndPlan(contexts.params, named_composition(extensions, n),
                                  extensions=extensions)  # fmt: skip
        cells, seconds = [], 0.0
        for controller in (DoNothing(), oracle, planner):
            started = time.process_time()
            returns = evaluate_policy(contexts, controller, extensions=extensions, seed=0).returns
            seconds = time.process_time() - started
            cells.append(
                f"{returns.mean():.4f} ± {returns.std(ddof=1) / np.sqrt(returns.size):.4f}"
            )
        print(f"| {latency} | " + " | ".join(cells) + f" | {seconds:.1f} |")


if __name__ == "__main__":
    main()
