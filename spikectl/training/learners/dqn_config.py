"""The settings of recurrent double Q-learning (paper Section 5, Table 2): the first
learner of the training loop (``spikectl.training.learners.dqn``).

A plain frozen dataclass with no Torch in sight, so that the config tree
(``spikectl.training.config``) can hold it without importing the learner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Literal

from spikectl.config_errors import ConfigError, check_int


class Schedules:
    """The exploration and learning-rate schedules of a Q-learner's config: pure
    functions of the episode count (a resumed run needs no scheduler state), read from
    the fields epsilon_start, epsilon_end, epsilon_anneal_fraction, learning_rate and
    learning_rate_end_fraction."""

    epsilon_start: float
    epsilon_end: float
    epsilon_anneal_fraction: float
    learning_rate: float
    learning_rate_end_fraction: float

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


@dataclass(frozen=True)
class DQNConfig(Schedules):
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
    learning_rate: float = 5e-4
    """Adam learning rate (at the start of training)."""
    learning_rate_end_fraction: float = 1.0
    """Learning rate at the last episode as a fraction of learning_rate, reached by linear
    decay over the run (1 = constant, the paper; 0 = decay to zero)."""
    gamma: float = 0.99
    """Discount factor."""
    tau: float = 0.1
    """Soft target-network update coefficient, applied after every gradient update."""
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
    n_step: int = 1
    """Steps of observed reward before bootstrapping (1 = the paper's one-step target)."""
    aux_voltage_weight: float = 0.0
    """Weight of the auxiliary loss predicting every neuron's next voltage (0 = off, paper)."""
    max_grad_norm: float = 10.0
    """Gradient-norm clip; 0 turns it off."""

    def __post_init__(self) -> None:
        for name in ("batch_size", "buffer_size", "n_step"):
            check_int(name, getattr(self, name), 1, what="a positive integer")
        for name in ("updates_per_round", "learning_starts"):
            check_int(name, getattr(self, name), 0, what="a non-negative integer")
        for name in ("learning_rate", "gamma", "tau", "epsilon_start", "epsilon_end",
                     "epsilon_anneal_fraction", "max_grad_norm", "aux_voltage_weight",
                     "learning_rate_end_fraction"):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(name, f"must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(name, f"must be finite, got {value!r}")
        if not self.aux_voltage_weight >= 0:
            raise ConfigError(
                "aux_voltage_weight", f"must be a finite number >= 0, got {self.aux_voltage_weight}"
            )
        if not self.learning_rate > 0:
            raise ConfigError("learning_rate", f"must be > 0, got {self.learning_rate}")
        if not 0 <= self.gamma <= 1:
            raise ConfigError("gamma", f"must lie in [0, 1], got {self.gamma}")
        if not 0 < self.tau <= 1:
            raise ConfigError("tau", f"must lie in (0, 1], got {self.tau}")
        for name in ("epsilon_start", "epsilon_end", "epsilon_anneal_fraction",
                     "learning_rate_end_fraction"):  # fmt: skip
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(name, f"must lie in [0, 1], got {getattr(self, name)}")
        if self.explore_do_nothing is not None and not 0 <= self.explore_do_nothing <= 1:
            raise ConfigError(
                "explore_do_nothing",
                f"must lie in [0, 1] or be None, got {self.explore_do_nothing}",
            )
        if self.loss not in ("mse", "huber"):
            raise ConfigError("loss", f"must be 'mse' or 'huber', got {self.loss!r}")
        if self.max_grad_norm < 0:
            raise ConfigError("max_grad_norm", f"must be >= 0, got {self.max_grad_norm}")
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
