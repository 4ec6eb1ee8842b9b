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
    labels: np.ndarray | None = None
    """[B, N] int64 a teacher's action at every step (NO_LABEL where none was asked), in
    a buffer made with ``labelled=True``; None otherwise."""
    target_inputs: np.ndarray | None = None
    """[B, n] int8 each observed neuron's synapse onto the target (-1, 0, +1), read from
    the training network's weights (privileged), in a buffer made with
    ``privileged=True``; None otherwise."""
    latency_steps: int = 0
    """L of the loop the episodes were played in (``Extensions.latency_steps``): the
    observations' actions in flight are the L actions before each step
    (:func:`~spikectl.training.learners.q_learning.sequence_observations`)."""


NO_LABEL = -2
"""The label of a step no teacher labelled (actions are >= -1)."""

_OPTIONAL_ARRAYS = {
    "labels": "teacher labels",
    "target_inputs": "the target's inputs (privileged)",
}
"""The arrays a buffer keeps only when made to, and how its errors name them."""


class EpisodeReplay:
    """A ring buffer of ``capacity`` whole episodes of length ``episode_length``."""

    def __init__(
        self,
        capacity: int,
        n_neurons: int,
        episode_length: int,
        labelled: bool = False,
        privileged: bool = False,
        latency_steps: int = 0,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"replay capacity must be >= 1 episode, got {capacity}")
        check_fits_in_memory(
            capacity
            * (
                (episode_length + 1) * n_neurons * 4
                + episode_length * (7 + 2 * labelled)
                + n_neurons * (1 + privileged)
                + 9
            ),
            f"a replay buffer of {capacity:,} episodes of {episode_length} steps and "
            f"{n_neurons} neurons",
            "lower buffer_size",
        )
        self.capacity = capacity
        self.n_neurons = n_neurons
        self.episode_length = episode_length
        self.latency_steps = latency_steps
        self.voltage = np.zeros((capacity, episode_length + 1, n_neurons), dtype=np.float32)
        self.actions = np.full((capacity, episode_length), DO_NOTHING, dtype=np.int16)
        self.rewards = np.zeros((capacity, episode_length), dtype=np.float32)
        self.targets = np.zeros(capacity, dtype=np.int64)
        self.patterns = np.zeros((capacity, episode_length), dtype=np.int8)
        self.action_masks = np.zeros((capacity, n_neurons + 1), dtype=bool)
        self.labels = (
            np.full((capacity, episode_length), NO_LABEL, dtype=np.int16) if labelled else None
        )
        self.target_inputs = np.zeros((capacity, n_neurons), dtype=np.int8) if privileged else None
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
        labels: np.ndarray | None = None,
        target_inputs: np.ndarray | None = None,
    ) -> None:
        """Add E finished episodes: voltage [E, N + 1, n], actions/rewards/patterns [E, N],
        targets [E], action_masks [E, n + 1]; in a labelled buffer, labels [E, N] (None:
        NO_LABEL everywhere); in a privileged buffer, target_inputs [E, n] (required)."""
        count = voltage.shape[0]
        expected = (count, self.episode_length + 1, self.n_neurons)
        if voltage.shape != expected or actions.shape != (count, self.episode_length):
            raise ValueError(
                f"episodes must be voltage {expected} and actions {(count, self.episode_length)}, "
                f"got {voltage.shape} and {actions.shape}"
            )
        if (self.target_inputs is None) != (target_inputs is None):
            raise ValueError(
                "a privileged replay buffer needs target_inputs with every episode, "
                "any other buffer refuses them"
            )
        if target_inputs is not None and target_inputs.shape != (count, self.n_neurons):
            raise ValueError(
                f"target_inputs must have shape {(count, self.n_neurons)}, "
                f"got {target_inputs.shape}"
            )
        slots = (self.added + np.arange(count)) % self.capacity
        self.voltage[slots] = voltage
        self.actions[slots] = actions
        self.rewards[slots] = rewards
        self.targets[slots] = targets
        self.patterns[slots] = patterns
        self.action_masks[slots] = action_masks
        if self.target_inputs is not None:
            self.target_inputs[slots] = target_inputs
        if self.labels is not None:
            if labels is not None and labels.shape != actions.shape:
                raise ValueError(f"labels must have shape {actions.shape}, got {labels.shape}")
            self.labels[slots] = NO_LABEL if labels is None else labels
        elif labels is not None:
            raise ValueError("this replay buffer keeps no labels (make it with labelled=True)")
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
            labels=None if self.labels is None else self.labels[slots].astype(np.int64),
            target_inputs=None if self.target_inputs is None else self.target_inputs[slots],
            latency_steps=self.latency_steps,
        )

    def state_dict(self) -> dict[str, np.ndarray | int]:
        """Everything needed to restore the buffer exactly (only the filled slots)."""
        held = slice(0, self.size)
        optional = {
            name: getattr(self, name)[held].copy()
            for name in _OPTIONAL_ARRAYS
            if getattr(self, name) is not None
        }
        return {
            **optional,
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
        if not 0 <= size <= min(self.capacity, int(state["added"])):
            raise ValueError(
                f"the checkpointed replay buffer holds {size} episodes of "
                f"{state['added']} added, capacity {self.capacity}"
            )
        for name, what in _OPTIONAL_ARRAYS.items():
            if (getattr(self, name) is None) != (name not in state):
                raise ValueError(
                    "the checkpointed replay buffer "
                    + ("keeps" if name in state else "does not keep")
                    + f" {what}, the configured one "
                    + ("does" if getattr(self, name) is not None else "does not")
                )
        names = ("voltage", "actions", "rewards", "targets", "patterns", "action_masks")
        optional = tuple(n for n in _OPTIONAL_ARRAYS if getattr(self, n) is not None)
        for name in names + optional:
            getattr(self, name)[:size] = state[name]
        # Indices the networks and the sampler use must lie in range (a crafted file's
        # would fail deep inside the first update).
        for name, low, high in (("actions", DO_NOTHING, self.n_neurons - 1),
                                ("targets", 0, self.n_neurons - 1),
                                ("target_inputs", -1, 1)):  # fmt: skip
            if getattr(self, name) is None:
                continue
            held = getattr(self, name)[:size]
            if held.size and not (low <= held.min() and held.max() <= high):
                raise ValueError(
                    f"the checkpointed replay buffer's {name} lie outside {low}..{high}"
                )
        self.size = size
        self.added = int(state["added"])
