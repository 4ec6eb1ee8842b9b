"""K single-seed learners as one group: each seed's block of the round is its own
learner's, so every seed trains exactly as it would alone."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.envs.rollout import EpisodeBatch
from spikectl.training.learners.protocol import Learner, LossDiverged, Policy


class LoopedLearners:
    """A LearnerGroup of K plain learners, called one after another."""

    def __init__(self, learners: list[Learner]) -> None:
        self.learners = learners
        self.size = len(learners)
        self.metric_fields = learners[0].metric_fields

    def collection_policy(self, episode: int) -> Policy:
        return BlockPolicy([learner.collection_policy(episode) for learner in self.learners])

    def observe(self, episodes: list[EpisodeBatch], contexts: list[np.ndarray]) -> None:
        for learner, seed_episodes, seed_contexts in zip(
            self.learners, episodes, contexts, strict=True
        ):
            learner.observe(seed_episodes, seed_contexts)

    def update(self, episode: int) -> None:
        for seed, learner in enumerate(self.learners):
            try:
                learner.update(episode)
            except LossDiverged as error:
                raise LossDiverged(error.value, error.update, seed) from None

    def network(self, seed: int) -> torch.nn.Module:
        return self.learners[seed].network

    def updates(self, seed: int) -> int:
        return self.learners[seed].updates

    def row_metrics(self, seed: int, episode: int) -> dict[str, float]:
        return self.learners[seed].row_metrics(episode)

    def progress(self, episode: int) -> dict[str, str]:
        return self.learners[0].progress(episode)

    def state_dict(self) -> dict[str, Any]:
        return {"seeds": [learner.state_dict() for learner in self.learners]}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        seeds = state["seeds"]
        if not isinstance(seeds, list) or len(seeds) != self.size:
            raise ValueError(f"the checkpoint holds {len(seeds)} seeds, the group has {self.size}")
        for learner, seed_state in zip(self.learners, seeds, strict=True):
            learner.load_state_dict(seed_state)


class BlockPolicy:
    """Plays K blocks of equally many sub-environments, block k with policy k."""

    def __init__(self, policies: list[Policy]) -> None:
        self.policies = policies

    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        K = len(self.policies)
        if K == 1:
            return self.policies[0](observations, action_mask)
        blocks = [
            ({key: value[k] for key, value in _split(observations, K).items()},
             np.split(action_mask, K)[k])
            for k in range(K)
        ]  # fmt: skip
        return np.concatenate(
            [policy(obs, mask) for policy, (obs, mask) in zip(self.policies, blocks, strict=True)]
        )


def _split(observations: dict[str, np.ndarray], K: int) -> dict[str, list[np.ndarray]]:
    """Each observation array [K*E, ...] as K blocks [E, ...]."""
    return {key: np.split(np.asarray(value), K) for key, value in observations.items()}
