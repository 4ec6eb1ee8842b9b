"""The settings of recurrent double Q-learning (paper Section 5, Table 2): the first
learner of the training loop (``spikectl.training.learners.dqn``).

A plain frozen dataclass with no Torch in sight, so that the config tree
(``spikectl.training.config``) can hold it without importing the learner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from spikectl.config_errors import ConfigError
from spikectl.training.learners.q_settings import QSettings


@dataclass(frozen=True)
class DQNConfig(QSettings):
    """Recurrent double Q-learning over whole episodes (paper Section 5, Table 2)."""

    name: ClassVar[str] = "dqn"
    """The learner's name in config.json (``"learner": {"name": "dqn", ...}``)."""

    updates_per_round: int = 10
    """Gradient updates after each collection round, each on a fresh batch."""
    batch_size: int = 5
    """Whole episodes per gradient update."""
    buffer_size: int = 16_667
    """Replay capacity in episodes (Table 2 stores every episode)."""
    learning_starts: int = 5
    """Episodes in the buffer before the first update."""
    tau: float = 0.1
    """Soft target-network update coefficient, applied after every gradient update."""
    n_step: int = 1
    """Steps of observed reward before bootstrapping (1 = the paper's one-step target)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("batch_size", "buffer_size", "n_step"):
            if getattr(self, name) < 1:
                raise ConfigError(name, f"must be a positive integer, got {getattr(self, name)}")
        for name in ("updates_per_round", "learning_starts"):
            if getattr(self, name) < 0:
                raise ConfigError(
                    name, f"must be a non-negative integer, got {getattr(self, name)}"
                )
        if not math.isfinite(self.tau):
            raise ConfigError("tau", f"must be finite, got {self.tau!r}")
        if not 0 < self.tau <= 1:
            raise ConfigError("tau", f"must lie in (0, 1], got {self.tau}")
        if self.batch_size > self.buffer_size:
            raise ConfigError("batch_size", "cannot exceed buffer_size")

    def check_episode_length(self, episode_length: int) -> None:
        """Refuse settings that do not fit episodes of ``episode_length`` steps."""
        if self.n_step > episode_length:
            raise ConfigError(
                "n_step",
                f"must be an integer in [1, episode_length = {episode_length}], "
                f"got {self.n_step!r}",
            )
