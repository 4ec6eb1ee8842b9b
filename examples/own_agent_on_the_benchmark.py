"""Your own controller on the frozen benchmark suite.

A controller is any object with ``reset()`` and ``act(observation, info) -> int``
(``spikectl.envs.controller.Controller``). ``spikectl.experiments.suite`` plays it on a
task's pinned networks under the suite's protocol and normalises its mean return
between doing nothing (0) and the oracle planner (1), exactly as
``spikectl benchmark CONTROLLER`` does for trained runs, compiled policies and the
built-in planners:

    spikectl benchmark identify-and-plan --task paper noise1
    spikectl benchmark runs/tdrqn-guided-seed0 --model best

Choose settings on the ``validation`` split; report the ``test`` split once.

    python examples/own_agent_on_the_benchmark.py [--task paper] [--split validation] [--short]
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from typing import Any

import numpy as np

from spikectl.experiments import suite


class PulseOnPattern:
    """Stimulates one neuron (drawn per episode from ``seed``) one step before each
    spike the target pattern wants."""

    def __init__(self, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.neuron = -1

    def reset(self) -> None:
        self.neuron = -1

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        if self.neuron < 0:
            legal = np.flatnonzero(info["action_mask"]) - 1  # -1 is "do nothing"
            self.neuron = int(self.rng.choice(legal[legal >= 0]))
        step = int(observation["step"])
        pattern = observation["pattern"]
        return self.neuron if step + 1 < len(pattern) and pattern[step + 1] else -1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="paper", choices=list(suite.suite_version(1).names()))
    parser.add_argument("--split", default="validation", choices=["validation", "test"])
    parser.add_argument("--seeds", type=int, default=3, help="the controller is random: seeds")
    parser.add_argument("--short", action="store_true", help="one seed (the tests)")
    args = parser.parse_args()
    seeds = 1 if args.short else args.seeds

    result = suite.score(args.task, args.split, PulseOnPattern, seeds=seeds)
    nothing, oracle = suite.references(args.task, args.split)
    normalised = suite.normalise(result.mean_return, nothing, oracle)
    print(
        f"task {args.task}, {args.split} split, {len(result.returns)} networks, "
        f"{seeds} seed(s): mean return {result.mean_return:.3f}, normalised {normalised:.3f} "
        f"(do nothing {nothing:.3f}, oracle {oracle:.3f}; {result.cpu_seconds:.1f} CPU s)"
    )


if __name__ == "__main__":
    main()
