"""A Gymnasium loop: play the environment with a policy of your own.

The policy here guesses one neuron per episode (it cannot see the synapses) and
stimulates it whenever the target pattern wants a spike within the next three steps:
a baseline to beat. The observation is a dict: ``voltage`` (mV, one per neuron),
``target``, ``pattern`` (the whole episode's), ``step`` and ``last_action``.

    python examples/gymnasium_loop.py [--episodes 20] [--short]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import spikectl  # noqa: F401  (registers the environment ids)


def play(env: gym.Env, episodes: int, seed: int) -> list[float]:
    """One return per episode of the guess-one-neuron policy."""
    returns = []
    for episode in range(episodes):
        observation, info = env.reset(seed=seed + episode)
        legal = np.flatnonzero(info["action_mask"]) - 1  # -1 is "do nothing"
        chosen = int(env.np_random.choice(legal[legal >= 0]))
        total, done = 0.0, False
        while not done:
            step = int(observation["step"])
            wants_spike_soon = bool(observation["pattern"][step : step + 3].any())
            action = chosen if wants_spike_soon else -1
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return returns


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--short", action="store_true", help="two episodes (the tests)")
    args = parser.parse_args()
    episodes = 2 if args.short else args.episodes

    env = gym.make("spikectl/NeuronControl-v0", split="test")  # 100 unseen networks
    returns = play(env, episodes, seed=0)
    print(f"guess-one-neuron: mean return {np.mean(returns):.3f} over {episodes} episodes")

    # The batched twin: many networks in one array call.
    envs = gym.make_vec("spikectl/NeuronControl-v0", num_envs=8, split="test")
    observations, infos = envs.reset(seed=0)
    do_nothing = np.full(8, -1)
    for _ in range(5):
        observations, rewards, terminated, truncated, infos = envs.step(do_nothing)
    print(f"vector env: {envs.num_envs} networks stepped, rewards {np.round(rewards, 3)}")
    envs.close()


if __name__ == "__main__":
    main()
