"""Throughput of the vector environment with the paper's pulse and with the ChR2 actuator.

Both are stepped in the same run, alternately, with the same random legal actions (a
pulse or light on a random neuron at most steps, so the opsin is busy); the time is
the median over repeats of whole episodes (resets excluded), in env steps per second.

    python benchmarks/bench_actuator.py [--num-envs 1 256 4096] [--repeats 7]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.envs.env_support import random_legal_actions
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions

SETTINGS = {"pulse": Extensions(), "chr2": Extensions(actuator="chr2")}


def episode_seconds(env: NeuronControlVectorEnv, seed: int) -> float:
    """Seconds of one episode's steps (every sub-environment from its reset)."""
    _, infos = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = [random_legal_actions(infos["action_mask"].astype(bool), rng)
               for _ in range(env.episode_length)]  # fmt: skip
    start = time.perf_counter()
    for step_actions in actions:
        env.step(step_actions)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, nargs="+", default=[1, 256, 4096])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    print("| num_envs | pulse (env steps/s) | chr2 (env steps/s) | chr2 / pulse time |")
    print("|---|---|---|---|")
    for num_envs in args.num_envs:
        envs = {name: NeuronControlVectorEnv(num_envs, contexts={"n_train": 100, "n_test": 100},
                                             extensions=extensions)
                for name, extensions in SETTINGS.items()}  # fmt: skip
        times = {name: [] for name in envs}
        for repeat in range(args.repeats + 1):  # the first compiles and is dropped
            for name, env in envs.items():
                seconds = episode_seconds(env, repeat)
                if repeat:
                    times[name].append(seconds)
        steps = num_envs * envs["pulse"].episode_length
        rate = {name: steps / float(np.median(values)) for name, values in times.items()}
        print(
            f"| {num_envs} | {rate['pulse']:,.0f} | {rate['chr2']:,.0f} | "
            f"{rate['pulse'] / rate['chr2']:.2f} |"
        )


if __name__ == "__main__":
    main()
