"""Is the student's passivity a bias of its do-nothing value? Play trained runs on a
task's validation networks with their do-nothing Q-value lowered by delta before the
greedy choice (no retraining), and print the mean return for each delta.

    python lab/results/belief-input/do_nothing_bias.py --task paper --run RUN ... \
        [--delta 0 0.005 0.01 0.02 0.05]

A run may name another size as RUN:32 (per-neuron networks). Validation only.
"""

from __future__ import annotations

import argparse

import torch

from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.training.controllers import load_agent
from spikectl.training.greedy import greedy_controller


class DoNothingBias(torch.nn.Module):
    """``network`` whose step forward scores do nothing (index 0) ``delta`` lower."""

    def __init__(self, network: torch.nn.Module, delta: float) -> None:
        super().__init__()
        self.network, self.delta = network, delta
        self.sizes = network.sizes  # what greedy_controller reads

    def step(self, obs, state):
        scores, state = self.network.step(obs, state)  # [S, n + 1]
        scores = scores.clone()
        scores[:, 0] -= self.delta
        return scores, state


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="paper")
    parser.add_argument("--run", action="append", required=True)
    parser.add_argument("--delta", type=float, nargs="+", default=[0, 0.005, 0.01, 0.02, 0.05])
    args = parser.parse_args()
    torch.set_num_threads(1)
    contexts = load_split(args.task, "validation")
    print(f"{args.task} validation, mean return with do nothing's Q lowered by delta")
    print("run".ljust(28) + "".join(f"{delta:>9g}" for delta in args.delta))
    for spec in args.run:
        run, _, size = spec.partition(":")
        network = load_agent(run, n_neurons=int(size) if size else None)
        returns = []
        for delta in args.delta:
            controller = greedy_controller(
                DoNothingBias(network, delta), contexts.params, contexts.extensions
            )
            returns.append(evaluate_policy(contexts, controller).returns.mean())
        print(spec.rsplit("/", 1)[-1].ljust(28) + "".join(f"{r:9.3f}" for r in returns))


if __name__ == "__main__":
    main()
