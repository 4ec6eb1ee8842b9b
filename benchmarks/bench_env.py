"""Environment step latency beside Gymnasium's CartPole, and vector-env throughput.

Both single environments are made with ``gymnasium.make`` (the same wrappers) and
stepped with random legal actions; the latency of ``step()`` alone is the median over
blocks of steps (resets excluded). The vector environment is stepped with do-nothing
actions at several batch sizes.

    python benchmarks/bench_env.py [--steps 20000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import spikectl  # noqa: F401  (registers the environment ids)
from spikectl.envs.vector_env import NeuronControlVectorEnv

BLOCK = 1000


def step_latency_us(env: gym.Env, steps: int, legal_actions) -> float:
    """Median over blocks of BLOCK steps of the mean time of one step() call."""
    rng = np.random.default_rng(0)
    _, info = env.reset(seed=0)
    blocks = []
    done_steps = 0
    while done_steps < steps:
        uniforms = rng.random(BLOCK)
        elapsed = 0.0
        for u in uniforms:
            legal = legal_actions(info)  # the context, and so the legal set, changes on reset
            action = int(legal[int(u * len(legal))])
            start = time.perf_counter()
            _, _, terminated, truncated, info = env.step(action)
            elapsed += time.perf_counter() - start
            if terminated or truncated:
                _, info = env.reset()
        blocks.append(elapsed / BLOCK)
        done_steps += BLOCK
    return float(np.median(blocks)) * 1e6


def spikectl_legal(info) -> np.ndarray:
    return np.flatnonzero(info["action_mask"]) - 1


def vector_rate(num_envs: int, repeats: int) -> tuple[float, float]:
    """(microseconds per vector step, env steps per second), medians over episodes."""
    env = NeuronControlVectorEnv(num_envs, contexts={"n_train": 100, "n_test": 100})
    actions = np.full(num_envs, -1)
    times = []
    for repeat in range(repeats + 1):
        env.reset(seed=repeat)
        start = time.perf_counter()
        for _ in range(env.episode_length):
            env.step(actions)
        if repeat:  # the first episode warms up
            times.append((time.perf_counter() - start) / env.episode_length)
    per_step = float(np.median(times))
    return per_step * 1e6, num_envs / per_step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cartpole = gym.make("CartPole-v1")
    neuron = gym.make("spikectl/NeuronControl-v0")
    step_latency_us(neuron, BLOCK, spikectl_legal)  # warm-up (JIT)
    rows = []
    for _ in range(args.repeats):  # interleaved, so both see the same machine load
        rows.append(
            (
                step_latency_us(cartpole, args.steps, lambda info: [0, 1]),
                step_latency_us(neuron, args.steps, spikectl_legal),
            )
        )
    cart, ours = np.median(np.array(rows), axis=0)
    ratio = np.median([b / a for a, b in rows])
    print("| environment (gymnasium.make) | step() median (µs) |")
    print("|---|---:|")
    print(f"| CartPole-v1 | {cart:.2f} |")
    print(f"| spikectl/NeuronControl-v0 (n = 8) | {ours:.2f} |")
    print(f"\nratio NeuronControl / CartPole: {ratio:.2f} (median of {args.repeats} paired runs)\n")
    print("| num_envs | vector step (µs) | env steps/s |")
    print("|---:|---:|---:|")
    for num_envs in (1, 16, 64, 256, 1024, 4096):
        micros, rate = vector_rate(num_envs, args.repeats)
        print(f"| {num_envs} | {micros:.1f} | {rate:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
