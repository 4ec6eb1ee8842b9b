"""The settings every Q-learner shares (the double-Q learner's, the guided learner's and
PQN's): Adam's learning rate and its decay, the discount, epsilon-greedy exploration, the
TD loss, the auxiliary next-voltage loss and the gradient clip, with their schedules.

A plain frozen dataclass with no Torch in sight, so that the config tree
(``spikectl.training.config``) can hold a learner's config without importing the learner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from spikectl.config_errors import ConfigError, check_field_types


@dataclass(frozen=True)
class QSettings:
    """Exploration, learning rate, discount and loss of a Q-learner; the schedules are
    pure functions of the episode count (a resumed run needs no scheduler state)."""

    learning_rate: float = 5e-4
    """Adam learning rate (at the start of training)."""
    learning_rate_end_fraction: float = 1.0
    """Learning rate at the last episode as a fraction of learning_rate, reached by linear
    decay over the run (1 = constant, the paper; 0 = decay to zero)."""
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
    """Weight of the auxiliary loss predicting every neuron's next voltage (0 = off, paper)."""
    max_grad_norm: float = 10.0
    """Gradient-norm clip; 0 turns it off."""

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("learning_rate", "learning_rate_end_fraction", "gamma", "epsilon_start",
                     "epsilon_end", "epsilon_anneal_fraction", "aux_voltage_weight",
                     "max_grad_norm"):  # fmt: skip
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(name, f"must be finite, got {getattr(self, name)!r}")
        if not self.learning_rate > 0:
            raise ConfigError("learning_rate", f"must be > 0, got {self.learning_rate}")
        for name in ("learning_rate_end_fraction", "gamma", "epsilon_start", "epsilon_end",
                     "epsilon_anneal_fraction"):  # fmt: skip
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(name, f"must lie in [0, 1], got {getattr(self, name)}")
        if self.explore_do_nothing is not None and not 0 <= self.explore_do_nothing <= 1:
            raise ConfigError(
                "explore_do_nothing",
                f"must lie in [0, 1] or be None, got {self.explore_do_nothing}",
            )
        if not self.aux_voltage_weight >= 0:
            raise ConfigError(
                "aux_voltage_weight", f"must be a finite number >= 0, got {self.aux_voltage_weight}"
            )
        if self.max_grad_norm < 0:
            raise ConfigError("max_grad_norm", f"must be >= 0, got {self.max_grad_norm}")

    def epsilon(self, episode: int, total_episodes: int) -> float:
        """Exploration rate for an episode: linear from start to end, then constant."""
        anneal = self.epsilon_anneal_fraction * total_episodes
        if anneal <= 0:
            return self.epsilon_end
        fraction = min(episode / anneal, 1.0)
        return self.epsilon_start + fraction * (self.epsilon_end - self.epsilon_start)

    def learning_rate_at(self, episode: int, total_episodes: int) -> float:
        """Adam's learning rate for the updates after the round that ends at ``episode``:
        linear from learning_rate to learning_rate x learning_rate_end_fraction."""
        fraction = min(episode / total_episodes, 1.0)
        return self.learning_rate * (1.0 + fraction * (self.learning_rate_end_fraction - 1.0))
