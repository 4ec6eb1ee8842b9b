"""What playing each environment alone costs: ``GreedyController(per_environment=True)``
beside the default batched forward (issue 40; docs/realtime.md, "The same actions alone
and in a batch").

A randomly initialised network of the quick preset (its architecture and sizes, a fixed
torch seed: the cost does not depend on what the weights learned) plays one greedy
episode on every context of a generated set, one Torch thread, in both ways, alternating
``--repeats`` times after a warm-up on two contexts. Reports the CPU seconds of each
(medians) and their ratio, from this one run, and the mean return of each (the two may
differ at near-ties: that is the point of ``per_environment``).

    python benchmarks/bench_per_environment.py [--contexts 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

import spikectl
from spikectl.agents import make_agent
from spikectl.agents.greedy import GreedyController
from spikectl.envs.rollout import evaluate_policy
from spikectl.training.presets import PRESETS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--contexts", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = PRESETS["quick"]
    n, length = config.env.n_neurons, config.env.episode_length
    torch.manual_seed(0)
    network = make_agent(config.agent.arch, n, length, config.agent.sizes,
                         params=config.env.params).eval()  # fmt: skip
    contexts = spikectl.ContextSet.generate(args.contexts, n, length, seed=5,
                                            params=config.env.params)  # fmt: skip
    for per_environment in (False, True):  # warm-up
        evaluate_policy(contexts[:2], GreedyController(network, per_environment=per_environment))
    seconds: dict[bool, list[float]] = {False: [], True: []}
    returns: dict[bool, float] = {}
    for _ in range(args.repeats):
        for per_environment in (False, True):
            started = time.process_time()
            episodes = evaluate_policy(
                contexts, GreedyController(network, per_environment=per_environment)
            )
            seconds[per_environment].append(time.process_time() - started)
            returns[per_environment] = float(episodes.returns.mean())
    batched, alone = statistics.median(seconds[False]), statistics.median(seconds[True])
    print(f"{config.agent.arch} (quick sizes, untrained), {args.contexts} contexts, n = {n}, "
          f"N = {length}, 1 thread, {args.repeats} repeats")  # fmt: skip
    print(f"batched forward   {batched:7.2f} CPU s   mean return {returns[False]:.5f}")
    print(f"per environment   {alone:7.2f} CPU s   mean return {returns[True]:.5f}")
    print(f"ratio             {alone / batched:7.1f}x")


if __name__ == "__main__":
    main()
