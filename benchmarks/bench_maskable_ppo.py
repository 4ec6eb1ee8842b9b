"""sb3-contrib's MaskablePPO on the paper's task through spikectl.wrappers (docs/ecosystem.md).

Trains MaskablePPO (MlpPolicy, SB3's defaults otherwise) on the 100 generated training
networks through ``sb3_vec_env``, then reports its greedy (deterministic, masked)
return on those networks and on the 100 unseen test networks, beside doing nothing
(0.5), and the training speed. Before that, the environment alone: random legal
actions through ``sb3_vec_env`` (one batched simulator call per step) against SB3's
``DummyVecEnv`` of ``sb3_compatible`` environments (one call per environment), median
of ``--repeats``. Needs ``pip install -e ".[sb3]"``.

    python benchmarks/bench_maskable_ppo.py [--steps 200000] [--num-envs 16] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import MaskablePPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

import spikectl  # noqa: F401  (registers the environment ids)
from spikectl.envs.env_support import random_legal_actions
from spikectl.wrappers import from_env_action, sb3_compatible, sb3_vec_env

ENV_ID = "spikectl/NeuronControl-v0"


def greedy_return(model: MaskablePPO, split: str) -> float:
    """Mean deterministic return over every network of the split, one episode each."""
    env = sb3_compatible(gym.make(ENV_ID, split=split))
    contexts = env.env.unwrapped.contexts
    returns = []
    for index in range(len(contexts)):
        obs, _ = env.reset(options={"context": index})
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            assert not info["illegal_action"]
            total, done = total + reward, terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def env_steps_per_s(venv: VecEnv, steps: int, repeats: int) -> float:
    """Median over ``repeats`` of environment steps per second with random legal actions."""
    rng = np.random.default_rng(0)
    venv.seed(0)
    venv.reset()
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps // venv.num_envs):
            masks = np.stack(venv.env_method("action_masks"))  # [num_envs, k + 1]
            actions = from_env_action(random_legal_actions(masks, rng))  # zero-based
            venv.step(actions)
        rates.append(steps / (time.perf_counter() - start))
    return float(np.median(rates))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000, help="environment steps")
    parser.add_argument("--num-envs", type=int, default=16, help="environments stepped at once")
    parser.add_argument("--seed", type=int, default=0, help="seed of the policy and the envs")
    parser.add_argument("--env-steps", type=int, default=20_000, help="steps per timing")
    parser.add_argument("--repeats", type=int, default=5, help="timings of the env alone")
    args = parser.parse_args()
    torch.set_num_threads(1)  # a busy neighbour slows two threads far more than one

    batched = sb3_vec_env(gym.make_vec(ENV_ID, num_envs=args.num_envs))
    dummy = DummyVecEnv([lambda: sb3_compatible(gym.make(ENV_ID))] * args.num_envs)
    batched_rate = env_steps_per_s(batched, args.env_steps, args.repeats)
    dummy_rate = env_steps_per_s(dummy, args.env_steps, args.repeats)
    print(f"environment alone, {args.num_envs} envs, random legal actions (steps/s, median):")
    print(
        f"  sb3_vec_env {batched_rate:.0f}, DummyVecEnv {dummy_rate:.0f}, "
        f"ratio {batched_rate / dummy_rate:.1f}x"
    )
    if args.steps == 0:
        return

    venv = sb3_vec_env(gym.make_vec(ENV_ID, num_envs=args.num_envs))
    model = MaskablePPO("MlpPolicy", venv, seed=args.seed, device="cpu")
    start, cpu_start = time.perf_counter(), time.process_time()
    model.learn(args.steps)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    print(f"MaskablePPO, {args.steps} steps, {args.num_envs} envs, seed {args.seed}")
    print(f"training: {wall:.0f} s wall, {cpu:.0f} s CPU, {args.steps / wall:.0f} steps/s")
    print("greedy return, do nothing = 0.500")
    for split in ("train", "test"):
        print(f"  {split:5s} {greedy_return(model, split):.3f}")


if __name__ == "__main__":
    main()
