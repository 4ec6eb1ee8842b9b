"""The settings of parallel Q-learning without replay (PQN, Gallici et al. 2024,
"Simplifying Deep Temporal Difference Learning"; ``spikectl.training.learners.pqn``), and
its preset.

A plain frozen dataclass with no Torch in sight (like :class:`DQNConfig`): the exploration
and learning-rate settings are every Q-learner's (:class:`QSettings`); there is no replay
buffer, no target network and no n-step setting (Q(lambda) returns take its place).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from spikectl.config_errors import ConfigError
from spikectl.training.learners.q_settings import QSettings
from spikectl.training.learners.registry import Preset


@dataclass(frozen=True)
class PQNConfig(QSettings):
    """Parallel recurrent Q-learning without replay or target network: Q(lambda) returns
    over each round's episodes, a few epochs of minibatches, then the episodes go."""

    name: ClassVar[str] = "pqn"
    """The learner's name in config.json (``"learner": {"name": "pqn", ...}``)."""

    epochs: int = 4
    """Passes over each round's episodes before they are discarded."""
    minibatch_size: int = 8
    """Whole episodes per gradient update (the last minibatch of an epoch may be smaller)."""
    q_lambda: float = 0.65
    """lambda of the Q(lambda) returns: 0 = one-step targets, 1 = Monte-Carlo returns."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("epochs", "minibatch_size"):
            if getattr(self, name) < 1:
                raise ConfigError(name, f"must be a positive integer, got {getattr(self, name)}")
        if not 0 <= self.q_lambda <= 1:
            raise ConfigError("q_lambda", f"must lie in [0, 1], got {self.q_lambda}")

    def check_episode_length(self, episode_length: int) -> None:
        """Every setting fits episodes of any length (the returns run over whole episodes)."""


def pqn_preset(presets: Mapping[str, Any]) -> Any:
    """The quick preset's environment, network (plus LayerNorm) and environment steps with
    parallel Q-learning without replay (docs/training.md, "Parallel Q-learning without
    replay"): 32 episodes a round (137 rounds, 4 384 episodes), 16 epochs of minibatches of
    8 episodes over each round (8 768 updates of 8 episodes, as quick's 8 800), Q(0.65)
    returns, the auxiliary loss and exploration of quick, lr 1e-3 decaying to 1e-4."""
    quick = presets["quick"]
    return dataclasses.replace(
        quick,
        agent=dataclasses.replace(
            quick.agent, sizes=dataclasses.replace(quick.agent.sizes, layer_norm=True)
        ),
        train=dataclasses.replace(quick.train, num_envs=32),
        learner=PQNConfig(
            epochs=16,
            minibatch_size=8,
            q_lambda=0.65,
            learning_rate=1e-3,
            learning_rate_end_fraction=0.1,
            gamma=0.9,
            aux_voltage_weight=1.0,
            explore_do_nothing=0.75,
        ),
    )


PRESETS = (
    Preset(
        "pqn",
        "The quick run with PQN: Q(lambda) on parallel episodes, no replay, LayerNorm.",
        pqn_preset,
    ),
)
"""The learner's presets (``spikectl train pqn``)."""
