"""Greedy play of a trained network: how the loop evaluates a learner, and how
``spikectl evaluate`` scores a saved model."""

from __future__ import annotations

import numpy as np
import torch

from spikectl.agents import greedy_action
from spikectl.agents.blocks import observation_batch
from spikectl.envs.rollout import run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv


class GreedyPolicy:
    """The legal action of highest score under ``network.step`` (scores [S, n + 1]),
    carrying one recurrent state per episode; a new instance starts every batch."""

    def __init__(self, network: torch.nn.Module, device: str = "cpu") -> None:
        self.network, self.device, self.state = network, device, None

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        obs = observation_batch(observations, self.device)
        scores, self.state = self.network.step(obs, self.state)  # [S, n + 1]
        legal = torch.as_tensor(action_mask, device=scores.device)
        return greedy_action(scores, legal).cpu().numpy()  # [S]


def greedy_returns(
    network: torch.nn.Module, env: NeuronControlVectorEnv, device: str, seed: int
) -> float:
    """Mean greedy return over every context of the environment's set (one batch); the
    environment's own draws (noise, ...) start from ``seed`` every time."""
    network.eval()
    env.reset(seed=seed)
    episodes = run_episodes(env, np.arange(env.num_envs), GreedyPolicy(network, device))
    network.train()
    return float(episodes.returns.mean())
