"""A trained Q-network as a controller: the legal action of highest Q-value.

``GreedyController(network)`` plays any of the four architectures (PyTorch, the
network's ``step`` forward) through the controller interface of
:mod:`spikectl.envs.controller`: ``reset()``, ``act(observation, info)`` on one
environment and ``act_batch(observations, infos)`` on a vector environment's batch. It
is what ``spikectl evaluate`` and the training loop's greedy evaluations play, and the
base of the learners' exploration policies, which call it as a bare policy function
``policy(observations, action_mask)``. For a decision in microseconds, export the
network to a :class:`~spikectl.agents.compiled.CompiledPolicy` (docs/realtime.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.agents.heads import greedy_action
from spikectl.agents.observation import observation_batch
from spikectl.envs.controller import check_controller_input


class GreedyController:
    """The legal action of highest score under ``network.step`` (scores [S, n + 1]),
    carrying one recurrent state per episode; every episode of a batch starts at step 0
    together, and a step-0 batch starts from the zero state."""

    def __init__(self, network: torch.nn.Module, device: str = "cpu") -> None:
        self.network, self.device, self.state = network, device, None

    def reset(self) -> None:
        """Forget the episodes: the next decision starts from the zero state."""
        self.state = None

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        if self.state is not None and not np.any(observations["step"]):
            self.state = None  # a new batch of episodes
        obs = observation_batch(observations, self.device)
        scores, self.state = self.network.step(obs, self.state)  # [S, n + 1]
        legal = torch.as_tensor(action_mask, device=scores.device)
        return greedy_action(scores, legal).cpu().numpy()  # [S]

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        """int64 [S]: one action per sub-environment."""
        check_controller_input(observations, infos, "GreedyController")
        return self(dict(observations), np.asarray(infos["action_mask"], dtype=bool))

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The action on one environment's observation (a batch of one)."""
        check_controller_input(observation, info, "GreedyController")
        observations = {key: np.asarray(value)[None] for key, value in observation.items()}
        mask = np.asarray(info["action_mask"], dtype=bool)[None]  # [1, n + 1]
        return int(self(observations, mask)[0])
