"""The episodic replay buffer: whole episodes in, uniformly sampled whole episodes out.

Episodes all have the environment's fixed length N, so the buffer is a set of
preallocated ring arrays indexed [slot, step]. Observations are stored for steps
0..N (N + 1 of them: the one after the last action is the bootstrap observation,
although the last step is terminal). Only what varies within an episode is stored
per step; the target, the pattern and the action mask are stored once per episode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.files import check_fits_in_memory
from spikectl.neuron.simulator import DO_NOTHING


@dataclass(frozen=True)
class EpisodeBatchArrays:
    """A sample of B whole episodes as NumPy arrays."""

    voltage: np.ndarray
    """[B, N + 1, n] float32 observed potentials (mV) before each step and after the last."""
    actions: np.ndarray
    """[B, N] int64 actions taken (-1 = do nothing)."""
    rewards: np.ndarray
    """[B, N] float32."""
    targets: np.ndarray
    """[B] int64."""
    patterns: np.ndarray
    """[B, N] int8."""
    action_masks: np.ndarray
    """[B, n + 1] bool legal actions (index a + 1 for action a)."""


class EpisodeReplay:
    """A ring buffer of ``capacity`` whole episodes of length ``episode_length``."""

    def __init__(self, capacity: int, n_neurons: int, episode_length: int) -> None:
        if capacity < 1:
            raise ValueError(f"replay capacity must be >= 1 episode, got {capacity}")
        check_fits_in_memory(
            capacity * ((episode_length + 1) * n_neurons * 4 + episode_length * 7 + n_neurons + 9),
            f"a replay buffer of {capacity:,} episodes of {episode_length} steps and "
            f"{n_neurons} neurons",
            "lower buffer_size",
        )
        self.capacity = capacity
        self.n_neurons = n_neurons
        self.episode_length = episode_length
        self.voltage = np.zeros((capacity, episode_length + 1, n_neurons), dtype=np.float32)
        self.actions = np.full((capacity, episode_length), DO_NOTHING, dtype=np.int16)
        self.rewards = np.zeros((capacity, episode_length), dtype=np.float32)
        self.targets = np.zeros(capacity, dtype=np.int64)
        self.patterns = np.zeros((capacity, episode_length), dtype=np.int8)
        self.action_masks = np.zeros((capacity, n_neurons + 1), dtype=bool)
        self.size = 0
        """Episodes currently held."""
        self.added = 0
        """Episodes ever added (the next slot is ``added % capacity``)."""

    def __len__(self) -> int:
        return self.size

    def add(
        self,
        voltage: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        targets: np.ndarray,
        patterns: np.ndarray,
        action_masks: np.ndarray,
    ) -> None:
        """Add E finished episodes: voltage [E, N + 1, n], actions/rewards/patterns [E, N],
        targets [E], action_masks [E, n + 1]."""
        count = voltage.shape[0]
        expected = (count, self.episode_length + 1, self.n_neurons)
        if voltage.shape != expected or actions.shape != (count, self.episode_length):
            raise ValueError(
                f"episodes must be voltage {expected} and actions {(count, self.episode_length)}, "
                f"got {voltage.shape} and {actions.shape}"
            )
        slots = (self.added + np.arange(count)) % self.capacity
        self.voltage[slots] = voltage
        self.actions[slots] = actions
        self.rewards[slots] = rewards
        self.targets[slots] = targets
        self.patterns[slots] = patterns
        self.action_masks[slots] = action_masks
        self.added += count
        self.size = min(self.size + count, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator) -> EpisodeBatchArrays:
        """``batch_size`` episodes drawn uniformly with replacement from those held."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        slots = rng.integers(self.size, size=batch_size)
        return EpisodeBatchArrays(
            voltage=self.voltage[slots],
            actions=self.actions[slots].astype(np.int64),
            rewards=self.rewards[slots],
            targets=self.targets[slots],
            patterns=self.patterns[slots],
            action_masks=self.action_masks[slots],
        )

    def state_dict(self) -> dict[str, np.ndarray | int]:
        """Everything needed to restore the buffer exactly (only the filled slots)."""
        held = slice(0, self.size)
        return {
            "capacity": self.capacity,
            "size": self.size,
            "added": self.added,
            "voltage": self.voltage[held].copy(),
            "actions": self.actions[held].copy(),
            "rewards": self.rewards[held].copy(),
            "targets": self.targets[held].copy(),
            "patterns": self.patterns[held].copy(),
            "action_masks": self.action_masks[held].copy(),
        }

    def load_state_dict(self, state: dict[str, np.ndarray | int]) -> None:
        if state["capacity"] != self.capacity:
            raise ValueError(
                f"checkpointed replay capacity {state['capacity']} != configured {self.capacity}"
            )
        size = int(state["size"])
        for name in ("voltage", "actions", "rewards", "targets", "patterns", "action_masks"):
            getattr(self, name)[:size] = state[name]
        self.size = size
        self.added = int(state["added"])
