"""The flat batched environment's throughput against the batched paper environment.

``gymnasium.make_vec("spikectl/NeuronControlFlat-v0", num_envs)`` (the flat ids'
batched entry point: zero-based actions, flat float32 observations, the illegal-action
rule) against ``NeuronControlVectorEnv`` on the same contexts, both stepped with
do-nothing actions. Times are this process's CPU time (``time.process_time``, so that
other programs on a shared machine do not count), medians over episodes of the two
interleaved; env steps/s is num_envs over the CPU time of one vector step, and the
ratio is the median of the paired per-episode ratios.

    python benchmarks/bench_flat_env.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import spikectl  # noqa: F401  (registers the environment ids)
from spikectl.envs.registration import FLAT_ENV_ID
from spikectl.envs.vector_env import NeuronControlVectorEnv

SIZES = (16, 64, 256, 1024)


def episode_seconds_per_step(env: gym.vector.VectorEnv, action: int, seed: int) -> float:
    """CPU seconds per vector step over one episode after a seeded reset."""
    actions = np.full(env.num_envs, action)
    env.reset(seed=seed)
    length = env.unwrapped.episode_length
    start = time.process_time()
    for _ in range(length):
        env.step(actions)
    return (time.process_time() - start) / length


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print("| num_envs | vector env steps/CPU-s | flat vector env steps/CPU-s | flat / vector |")
    print("|---:|---:|---:|---:|")
    for num_envs in SIZES:
        paper = NeuronControlVectorEnv(num_envs, contexts={"n_train": 100, "n_test": 100})
        flat = gym.make_vec(FLAT_ENV_ID, num_envs, contexts={"n_train": 100, "n_test": 100})
        rows = []
        for repeat in range(args.repeats + 1):
            row = (
                episode_seconds_per_step(paper, -1, repeat),
                episode_seconds_per_step(flat, 0, repeat),
            )
            if repeat:  # the first episode warms up
                rows.append(row)
        paper_s, flat_s = np.median(np.array(rows), axis=0)
        ratio = np.median([a / b for a, b in rows])
        print(
            f"| {num_envs} | {num_envs / paper_s:,.0f} | {num_envs / flat_s:,.0f} "
            f"| {ratio:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
