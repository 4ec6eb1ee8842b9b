"""The settings of parallel Q-learning without replay (PQN, Gallici et al. 2024,
"Simplifying Deep Temporal Difference Learning"; ``spikectl.training.learners.pqn``).

A plain frozen dataclass with no Torch in sight (like :class:`DQNConfig`): the exploration
and learning-rate settings mean what they mean there; there is no replay buffer, no
target network and no n-step setting (Q(lambda) returns take its place).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Literal

from spikectl.config_errors import ConfigError, check_int
from spikectl.training.learners.dqn_config import Schedules


@dataclass(frozen=True)
class PQNConfig(Schedules):
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
    learning_rate: float = 5e-4
    """Adam learning rate (at the start of training)."""
    learning_rate_end_fraction: float = 1.0
    """Learning rate at the last episode as a fraction of learning_rate (linear decay)."""
    gamma: float = 0.99
    """Discount factor."""
    epsilon_start: float = 1.0
    """Initial exploration rate."""
    epsilon_end: float = 0.05
    """Final exploration rate."""
    epsilon_anneal_fraction: float = 0.25
    """Fraction of all episodes over which epsilon decays linearly."""
    explore_do_nothing: float | None = None
    """Chance that an exploratory action is "do nothing" (None: uniform over legal actions)."""
    loss: Literal["mse", "huber"] = "mse"
    """TD loss: mean squared error or Huber (smooth L1, delta 1)."""
    aux_voltage_weight: float = 0.0
    """Weight of the auxiliary loss predicting every neuron's next voltage (0 = off)."""
    max_grad_norm: float = 10.0
    """Gradient-norm clip; 0 turns it off."""

    def __post_init__(self) -> None:
        for name in ("epochs", "minibatch_size"):
            check_int(name, getattr(self, name), 1, what="a positive integer")
        for name in ("q_lambda", "learning_rate", "learning_rate_end_fraction", "gamma",
                     "epsilon_start", "epsilon_end", "epsilon_anneal_fraction",
                     "aux_voltage_weight", "max_grad_norm"):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(name, f"must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(name, f"must be finite, got {value!r}")
        for name in ("q_lambda", "learning_rate_end_fraction", "gamma", "epsilon_start",
                     "epsilon_end", "epsilon_anneal_fraction"):  # fmt: skip
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(name, f"must lie in [0, 1], got {getattr(self, name)}")
        if not self.learning_rate > 0:
            raise ConfigError("learning_rate", f"must be > 0, got {self.learning_rate}")
        for name in ("aux_voltage_weight", "max_grad_norm"):
            if getattr(self, name) < 0:
                raise ConfigError(name, f"must be >= 0, got {getattr(self, name)}")
        if self.explore_do_nothing is not None and not (
            isinstance(self.explore_do_nothing, (int, float))
            and not isinstance(self.explore_do_nothing, bool)
            and 0 <= self.explore_do_nothing <= 1
        ):
            raise ConfigError(
                "explore_do_nothing",
                f"must lie in [0, 1] or be None, got {self.explore_do_nothing!r}",
            )
        if self.loss not in ("mse", "huber"):
            raise ConfigError("loss", f"must be 'mse' or 'huber', got {self.loss!r}")

    def check_episode_length(self, episode_length: int) -> None:
        """Every setting fits episodes of any length (the returns run over whole episodes)."""
