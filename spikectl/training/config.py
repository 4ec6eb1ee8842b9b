"""The trainer's typed configuration and its presets (SPEC section 5, paper Table 2).

``TrainConfig`` is a frozen dataclass; tyro turns it into the command line, one flag
per field, with the docstrings below as help. Presets are plain instances:

- ``paper``: Table 2 exactly (1 M environment steps, batches of 5 episodes, ...);
- ``quick``: the README's main job, under 15 minutes on one CPU core;
- ``smoke``: seconds, for tests.

How often a batch is drawn is not in the paper. This project's reading: episodes are
collected ``num_envs`` at a time (one round); after each round, ``updates_per_round``
gradient updates follow, each on ``batch_size`` whole episodes sampled uniformly from
the buffer. The paper preset collects 5 episodes per round and makes 10 updates
(Table 2's "10 gradient updates per batch" of 5 episodes): 33 333 updates in 1 M steps.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from spikectl.agents import ARCHITECTURES, AgentSizes, Architecture
from spikectl.contexts import MAX_EPISODE_LENGTH, MAX_N_NEURONS


@dataclass(frozen=True)
class TrainConfig:
    """Recurrent double Q-learning on generated contexts (paper Section 5, Table 2)."""

    arch: Architecture = "tdrqn"
    """Q-network architecture."""
    seed: int = 0
    """Seed of the network initialisation, exploration and replay sampling."""
    total_env_steps: int = 1_000_000
    """Environment steps to train for (episodes = total_env_steps / episode_length)."""

    n_neurons: int = 8
    """Neurons per network."""
    episode_length: int = 60
    """Steps per episode (N)."""
    n_train: int = 100
    """Training contexts (generated when train_contexts is not given)."""
    n_test: int = 100
    """Unseen test contexts (generated when test_contexts is not given)."""
    n_val: int = 100
    """Validation contexts, disjoint from both sets, for choosing settings (0 = none)."""
    context_seed: int = 0
    """Seed of the context generation (make_splits)."""
    train_contexts: Path | None = None
    """A saved ContextSet to train on instead of generated contexts."""
    test_contexts: Path | None = None
    """A saved ContextSet to evaluate on instead of generated contexts."""

    num_envs: int = 5
    """Episodes collected in parallel per round (one vector-env batch)."""
    updates_per_round: int = 10
    """Gradient updates after each collection round, each on a fresh batch."""
    batch_size: int = 5
    """Whole episodes per gradient update."""
    buffer_size: int = 16_667
    """Replay capacity in episodes (Table 2 stores every episode)."""
    learning_starts: int = 5
    """Episodes in the buffer before the first update."""
    learning_rate: float = 5e-4
    """Adam learning rate."""
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
    sizes: AgentSizes = field(default_factory=AgentSizes)
    """Network sizes: the preset's (Table 2's with --preset paper), then these flags."""

    eval_every_episodes: int = 500
    """Greedy evaluation on every training and test context every this many episodes."""
    checkpoint_every_episodes: int = 500
    """Write a resumable checkpoint every this many episodes (and at the end)."""
    device: str = "cpu"
    """Torch device: cpu, cuda, cuda:1, ..."""
    torch_threads: int = 1
    """Torch intra-op threads (0: Torch's default). 1 is robust on a shared machine
    (docs/benchmarks.md); bit-identical reruns need the same number."""
    progress: bool = True
    """Show a progress bar."""

    def __post_init__(self) -> None:
        positive = (
            "total_env_steps", "n_neurons", "episode_length", "n_train", "n_test", "num_envs",
            "batch_size", "buffer_size", "eval_every_episodes", "checkpoint_every_episodes",
        )  # fmt: skip
        for name in positive:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if isinstance(self.n_step, bool) or not isinstance(self.n_step, int) or not (
            1 <= self.n_step <= self.episode_length
        ):
            raise ValueError(
                f"n_step must be an integer in [1, episode_length = {self.episode_length}], "
                f"got {self.n_step!r}"
            )
        if not 0 <= self.aux_voltage_weight < math.inf:
            raise ValueError(
                f"aux_voltage_weight must be a finite number >= 0, got {self.aux_voltage_weight}"
            )
        for name in ("updates_per_round", "learning_starts", "torch_threads", "n_val"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
        if self.arch not in ARCHITECTURES:
            raise ValueError(f"arch must be one of {ARCHITECTURES}, got {self.arch!r}")
        for name in ("n_neurons", "episode_length"):
            if getattr(self, name) < 2:
                raise ValueError(f"{name} must be >= 2, got {getattr(self, name)}")
        if self.total_env_steps < self.episode_length * self.num_envs:
            raise ValueError(
                f"total_env_steps ({self.total_env_steps}) is less than one round of "
                f"num_envs x episode_length ({self.num_envs * self.episode_length})"
            )
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate}")
        if not 0 <= self.gamma <= 1:
            raise ValueError(f"gamma must lie in [0, 1], got {self.gamma}")
        if not 0 < self.tau <= 1:
            raise ValueError(f"tau must lie in (0, 1], got {self.tau}")
        for name in ("epsilon_start", "epsilon_end", "epsilon_anneal_fraction"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        if self.explore_do_nothing is not None and not 0 <= self.explore_do_nothing <= 1:
            raise ValueError(
                f"explore_do_nothing must lie in [0, 1] or be None, got {self.explore_do_nothing}"
            )
        if self.loss not in ("mse", "huber"):
            raise ValueError(f"loss must be 'mse' or 'huber', got {self.loss!r}")
        if self.max_grad_norm < 0:
            raise ValueError(f"max_grad_norm must be >= 0, got {self.max_grad_norm}")
        if self.batch_size > self.buffer_size:
            raise ValueError("batch_size cannot exceed buffer_size")
        self._check_ranges()

    def _check_ranges(self) -> None:
        """Seeds, sizes and rates that would wrap, allocate without bound or poison a run."""
        for name in ("seed", "context_seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**63:
                raise ValueError(f"{name} must be an integer in 0..2**63 - 1, got {value!r}")
        if self.n_neurons > MAX_N_NEURONS:
            raise ValueError(
                f"n_neurons must be at most {MAX_N_NEURONS} (MAX_N_NEURONS), got {self.n_neurons}"
            )
        if self.episode_length > MAX_EPISODE_LENGTH:
            raise ValueError(
                f"episode_length must be at most {MAX_EPISODE_LENGTH}, got {self.episode_length}"
            )
        for name in ("learning_rate", "gamma", "tau", "epsilon_start", "epsilon_end",
                     "epsilon_anneal_fraction", "max_grad_norm"):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
        if not isinstance(self.device, str) or not self.device:
            raise ValueError(f"device must be a string such as cpu or cuda, got {self.device!r}")

    @property
    def total_episodes(self) -> int:
        """Whole rounds of num_envs episodes that fit in total_env_steps."""
        rounds = self.total_env_steps // (self.episode_length * self.num_envs)
        return rounds * self.num_envs

    def epsilon(self, episode: int) -> float:
        """Exploration rate for an episode: linear from start to end, then constant."""
        anneal = self.epsilon_anneal_fraction * self.total_episodes
        if anneal <= 0:
            return self.epsilon_end
        fraction = min(episode / anneal, 1.0)
        return self.epsilon_start + fraction * (self.epsilon_end - self.epsilon_start)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (paths as strings, sizes nested)."""
        values = dataclasses.asdict(self)
        for key, value in values.items():
            if isinstance(value, Path):
                values[key] = str(value)
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`; unknown fields are an error."""
        values = dict(values)
        # Runs saved before the validation split existed had none.
        values.setdefault("n_val", 0)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown TrainConfig field(s): {', '.join(unknown)}")
        sizes = dict(values.pop("sizes", {}))
        size_fields = {f.name: f for f in dataclasses.fields(AgentSizes)}
        unknown_sizes = sorted(set(sizes) - set(size_fields))
        if unknown_sizes:
            raise ValueError(f"unknown AgentSizes field(s): {', '.join(unknown_sizes)}")
        for name, value in sizes.items():
            if isinstance(value, list):
                sizes[name] = tuple(value)
        for name in ("train_contexts", "test_contexts"):
            if values.get(name) is not None:
                values[name] = Path(values[name])
        return cls(sizes=AgentSizes(**sizes), **values)


PAPER = TrainConfig()

QUICK = TrainConfig(
    total_env_steps=264_000,
    num_envs=16,
    updates_per_round=32,
    batch_size=8,
    buffer_size=40_000,
    learning_starts=16,
    learning_rate=2e-3,
    gamma=0.9,
    tau=0.05,
    n_step=3,
    aux_voltage_weight=1.0,
    explore_do_nothing=0.75,
    sizes=AgentSizes(
        lstm_hidden=64,
        attn_width=64,
        attn_ff=128,
        tdrqn_head_hidden=(128, 64),
        ff_hidden=256,
        head_hidden=(256, 128, 64),
        target_voltage_in_input=True,
    ),
    eval_every_episodes=400,
    checkpoint_every_episodes=800,
    torch_threads=1,
)
"""The README's main job: ~14 minutes on one core of the project's 2-core machine
(docs/training.md, "Learning fast"): 4 400 episodes, 8 800 updates of 8 episodes,
n-step targets, the auxiliary next-voltage loss, the target's voltage in each neuron's
input, do-nothing-biased exploration, gamma 0.9, lr 2e-3, half-width networks, one Torch
thread."""

SMOKE = TrainConfig(
    total_env_steps=40 * 20 * 8,
    episode_length=20,
    n_neurons=5,
    n_train=6,
    n_test=6,
    n_val=6,
    num_envs=8,
    updates_per_round=2,
    batch_size=4,
    buffer_size=200,
    learning_starts=8,
    learning_rate=1e-3,
    sizes=AgentSizes(
        lstm_hidden=16,
        target_embed=4,
        pattern_embed=4,
        ff_hidden=32,
        head_hidden=(32,),
        tdrqn_head_hidden=(32,),
        attn_width=16,
        attn_ff=32,
        value_hidden=(16,),
    ),
    eval_every_episodes=80,
    checkpoint_every_episodes=80,
    torch_threads=1,
    progress=False,
)

PRESETS: dict[str, TrainConfig] = {"paper": PAPER, "quick": QUICK, "smoke": SMOKE}
