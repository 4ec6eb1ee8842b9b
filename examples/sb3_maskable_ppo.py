"""MaskablePPO (sb3-contrib) on the environment through ``spikectl.wrappers``.

``sb3_vec_env`` gives Stable-Baselines3 zero-based action spaces, bounded observations
and ``action_masks()`` on the batched environment; MaskablePPO needs no other wrapper.
Needs the sb3 extra: ``pip install -c constraints.txt -e ".[sb3]"``.

    python examples/sb3_maskable_ppo.py [--steps 200000] [--short]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import spikectl  # noqa: F401  (registers the environment ids)
from spikectl.wrappers import sb3_compatible, sb3_vec_env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--episodes", type=int, default=20, help="greedy test episodes")
    parser.add_argument("--short", action="store_true", help="a few hundred steps (tests)")
    args = parser.parse_args()
    from sb3_contrib import MaskablePPO  # the sb3 extra

    steps, episodes = (256, 2) if args.short else (args.steps, args.episodes)
    venv = sb3_vec_env(gym.make_vec("spikectl/NeuronControl-v0", num_envs=16))
    model = MaskablePPO("MlpPolicy", venv, n_steps=16 if args.short else 2048, seed=0)
    model.learn(steps)

    env = sb3_compatible(gym.make("spikectl/NeuronControl-v0", split="test"))
    returns = []
    for episode in range(episodes):
        obs, info = env.reset(seed=episode)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    print(
        f"MaskablePPO after {steps} steps: greedy return {np.mean(returns):.3f} "
        f"on {episodes} unseen networks"
    )


if __name__ == "__main__":
    main()
