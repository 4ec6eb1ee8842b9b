"""The training loop's scores: a network's mean greedy return on every context of a set
(its evaluations of the validation and test sets during a run)."""

from __future__ import annotations

import numpy as np
import torch

from spikectl.agents.greedy import GreedyController
from spikectl.envs.rollout import run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv


def greedy_returns(
    network: torch.nn.Module, env: NeuronControlVectorEnv, device: str, seed: int
) -> float:
    """Mean greedy return over every context of the environment's set (one batch); the
    environment's own draws (noise, ...) start from ``seed`` every time."""
    network.eval()
    env.reset(seed=seed)
    controller = GreedyController(network, device)
    episodes = run_episodes(env, np.arange(env.num_envs), controller)
    network.train()
    return float(episodes.returns.mean())
