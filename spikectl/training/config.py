"""The typed configuration tree of a training run and its presets (SPEC 5, paper Table 2).

One tree is the single source of truth for a run: what it trains on, what it trains
and how::

    Experiment(
        env=EnvConfig(id, n_neurons, episode_length, n_train, n_test, n_val, context_seed,
                      train_contexts, test_contexts, params=NeuronParams(...),
                      extensions=Extensions(...)),
        agent=AgentConfig(arch, sizes=AgentSizes(...)),
        train=TrainConfig(seed, total_env_steps, num_envs, ..., device, torch_threads),
    )

Every part is a frozen dataclass with a one-line docstring per field; tyro turns the
tree into the command line (``spikectl train``), ``config.json`` stores it
(:meth:`Experiment.to_dict`) and everything that rebuilds a run (resume, evaluate,
sweep, plot, seed groups) reads it back (:meth:`Experiment.from_dict`, which also reads
the flat configs of runs saved before the tree). The agent's voltage normalisation is
the environment's ``params`` (V_r and V_th), never a second copy.

The presets (paper, quick, smoke) are instances of the tree, in
``spikectl.training.presets``.

How often a batch is drawn is not in the paper. This project's reading: episodes are
collected ``num_envs`` at a time (one round); after each round, ``updates_per_round``
gradient updates follow, each on ``batch_size`` whole episodes sampled uniformly from
the buffer. The paper preset collects 5 episodes per round and makes 10 updates
(Table 2's "10 gradient updates per batch" of 5 episodes): 33 333 updates in 1 M steps.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import tyro

from spikectl.agents import ARCHITECTURES, AgentSizes, Architecture
from spikectl.contexts import MAX_EPISODE_LENGTH, MAX_N_NEURONS
from spikectl.envs.registration import ENV_ID
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.training.variants import flat_settings, split_settings, variant_settings


def _check_int(name: str, value: Any, low: int, high: int | None = None, what: str = "") -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < low
        or (high is not None and value > high)
    ):
        raise ValueError(f"{name} must be {what}, got {value!r}")


@dataclass(frozen=True)
class EnvConfig:
    """What the agent trains on: a registered environment, its context sets, its model."""

    id: Annotated[str, tyro.conf.arg(name="env")] = ENV_ID
    """Registered environment id; its n_neurons, params and extensions are the defaults."""
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
    params: NeuronParams = field(default_factory=NeuronParams)
    """Neuron and synapse model (Table 1); V_r and V_th also normalise the agent's input."""
    extensions: Extensions = field(default_factory=Extensions)
    """Extensions of the paper's environment (docs/extensions.md); all off by default."""

    def __post_init__(self) -> None:
        if not isinstance(self.id, str):
            raise ValueError(f"env must be a registered environment id, got {self.id!r}")
        _check_int("n_neurons", self.n_neurons, 2, MAX_N_NEURONS,
                   f"an integer in 2..{MAX_N_NEURONS} (MAX_N_NEURONS)")  # fmt: skip
        _check_int("episode_length", self.episode_length, 2, MAX_EPISODE_LENGTH,
                   f"an integer in 2..{MAX_EPISODE_LENGTH} (MAX_EPISODE_LENGTH)")  # fmt: skip
        for name in ("n_train", "n_test"):
            _check_int(name, getattr(self, name), 1, what="a positive integer")
        _check_int("n_val", self.n_val, 0, what="a non-negative integer")
        _check_int("context_seed", self.context_seed, 0, 2**63 - 1, "an integer in 0..2**63 - 1")
        for name, kind in (("params", NeuronParams), ("extensions", Extensions)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"{name} must be a {kind.__name__}, got {getattr(self, name)!r}")
        self._check_variant()
        try:
            self.extensions.hidden_count(self.n_neurons)  # at least 2 observable neurons
        except ValueError as error:
            name = "hidden_neurons" if self.extensions.hidden_neurons else "hidden_fraction"
            raise ValueError(f"extensions.{name}: {error}") from None

    def _settings(self) -> dict[str, Any]:
        sizes = {"n_neurons": self.n_neurons, "episode_length": self.episode_length}
        return flat_settings(sizes, self.params, self.extensions)

    def _check_variant(self) -> None:
        """Refuse a setting the variant changes that is still the base environment's:
        ``EnvConfig(id=variant)`` alone would otherwise train without the variant."""
        base, mine = _base_settings(), self._settings()
        for name, value in variant_settings(self.id).items():
            if mine[name] == base[name] != value:
                raise ValueError(
                    f"env: {self.id} sets {name} = {value!r}, but this config has the base "
                    f"environment's {mine[name]!r}: take the variant's settings with "
                    f"EnvConfig.with_variant / with_changes({{'env.id': ...}}), or use "
                    f"{ENV_ID} to leave that setting at the paper's"
                )

    @property
    def n_observed(self) -> int:
        """Neurons the agent observes and may stimulate (all but the hidden ones)."""
        return self.n_neurons - self.extensions.hidden_count(self.n_neurons)

    def with_variant(self, env_id: str) -> EnvConfig:
        """This config on the registered variant ``env_id``: what the current id's variant
        set goes back to the base environment's, then ``env_id``'s settings (n_neurons,
        episode_length, single params and extensions fields) apply; all else (set sizes,
        seeds, a preset's episode length, ...) stays."""
        base, settings = _base_settings(), self._settings()
        settings.update({name: base[name] for name in variant_settings(self.id)})
        settings.update(variant_settings(env_id))
        return dataclasses.replace(self, id=env_id, **split_settings(settings))


def _base_settings() -> dict[str, Any]:
    """The base environment's value of every setting a variant may change."""
    fields = {f.name: f.default for f in dataclasses.fields(EnvConfig)}
    return flat_settings(fields, NeuronParams(), Extensions())


@dataclass(frozen=True)
class AgentConfig:
    """The recurrent Q-network (paper Section 5.2)."""

    arch: Architecture = "tdrqn"
    """Q-network architecture."""
    sizes: AgentSizes = field(default_factory=AgentSizes)
    """Network sizes and input settings (the preset's, then these flags)."""

    def __post_init__(self) -> None:
        if self.arch not in ARCHITECTURES:
            raise ValueError(f"arch must be one of {ARCHITECTURES}, got {self.arch!r}")
        if not isinstance(self.sizes, AgentSizes):
            raise ValueError(f"sizes must be an AgentSizes, got {self.sizes!r}")


@dataclass(frozen=True)
class TrainConfig:
    """Recurrent double Q-learning on the environment's contexts (paper Section 5, Table 2)."""

    seed: int = 0
    """Seed of the network initialisation, exploration and replay sampling."""
    total_env_steps: int = 1_000_000
    """Environment steps to train for (episodes = total_env_steps / episode_length)."""
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
        positive = ("total_env_steps", "num_envs", "batch_size", "buffer_size",
                    "eval_every_episodes", "checkpoint_every_episodes", "n_step")  # fmt: skip
        for name in positive:
            _check_int(name, getattr(self, name), 1, what="a positive integer")
        for name in ("updates_per_round", "learning_starts", "torch_threads"):
            _check_int(name, getattr(self, name), 0, what="a non-negative integer")
        _check_int("seed", self.seed, 0, 2**63 - 1, "an integer in 0..2**63 - 1")
        for name in ("learning_rate", "gamma", "tau", "epsilon_start", "epsilon_end",
                     "epsilon_anneal_fraction", "max_grad_norm", "aux_voltage_weight",
                     "learning_rate_end_fraction"):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
        if not self.aux_voltage_weight >= 0:
            raise ValueError(
                f"aux_voltage_weight must be a finite number >= 0, got {self.aux_voltage_weight}"
            )
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate}")
        if not 0 <= self.gamma <= 1:
            raise ValueError(f"gamma must lie in [0, 1], got {self.gamma}")
        if not 0 < self.tau <= 1:
            raise ValueError(f"tau must lie in (0, 1], got {self.tau}")
        for name in ("epsilon_start", "epsilon_end", "epsilon_anneal_fraction",
                     "learning_rate_end_fraction"):  # fmt: skip
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
        if not isinstance(self.device, str) or not self.device:
            raise ValueError(f"device must be a string such as cpu or cuda, got {self.device!r}")


@dataclass(frozen=True)
class Experiment:
    """One training run: the environment, the agent and the training algorithm."""

    env: Annotated[EnvConfig, tyro.conf.arg(name="")] = field(default_factory=EnvConfig)
    """What the agent trains on."""
    agent: Annotated[AgentConfig, tyro.conf.arg(name="")] = field(default_factory=AgentConfig)
    """The Q-network."""
    train: Annotated[TrainConfig, tyro.conf.arg(name="")] = field(default_factory=TrainConfig)
    """The training algorithm."""

    def __post_init__(self) -> None:
        for name, kind in (("env", EnvConfig), ("agent", AgentConfig), ("train", TrainConfig)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"{name} must be a {kind.__name__}, got {getattr(self, name)!r}")
        length, train = self.env.episode_length, self.train
        if train.n_step > length:
            raise ValueError(
                f"n_step must be an integer in [1, episode_length = {length}], got {train.n_step!r}"
            )
        if train.total_env_steps < length * train.num_envs:
            raise ValueError(
                f"total_env_steps ({train.total_env_steps}) is less than one round of "
                f"num_envs x episode_length ({train.num_envs * length})"
            )

    @property
    def total_episodes(self) -> int:
        """Whole rounds of num_envs episodes that fit in total_env_steps."""
        rounds = self.train.total_env_steps // (self.env.episode_length * self.train.num_envs)
        return rounds * self.train.num_envs

    def epsilon(self, episode: int) -> float:
        """Exploration rate for an episode: linear from start to end, then constant."""
        train = self.train
        anneal = train.epsilon_anneal_fraction * self.total_episodes
        if anneal <= 0:
            return train.epsilon_end
        fraction = min(episode / anneal, 1.0)
        return train.epsilon_start + fraction * (train.epsilon_end - train.epsilon_start)

    def learning_rate(self, episode: int) -> float:
        """Adam's learning rate for the updates after the round that ends at ``episode``:
        linear from learning_rate to learning_rate x learning_rate_end_fraction."""
        train = self.train
        fraction = min(episode / self.total_episodes, 1.0)
        return train.learning_rate * (1.0 + fraction * (train.learning_rate_end_fraction - 1.0))

    def with_seed(self, seed: int) -> Experiment:
        """The same experiment with another training seed."""
        return dataclasses.replace(self, train=dataclasses.replace(self.train, seed=seed))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict: {"env": {..., "params": {...}, "extensions": {...}},
        "agent": {"arch": ..., "sizes": {...}}, "train": {...}} (paths as strings)."""
        values = dataclasses.asdict(self)
        for name in ("train_contexts", "test_contexts"):
            if values["env"][name] is not None:
                values["env"][name] = str(values["env"][name])
        values["agent"]["sizes"] = {
            key: list(value) if isinstance(value, tuple) else value
            for key, value in values["agent"]["sizes"].items()
        }
        return values

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Experiment:
        """Inverse of :meth:`to_dict`; also reads the flat config of a run saved before
        the tree (see :func:`nest`). Unknown fields are an error."""
        nested = nest(values)
        if isinstance(values, Mapping) and not any(key in SECTIONS for key in values):
            # A flat config of a run saved before the validation split existed had none.
            nested.setdefault("env", {}).setdefault("n_val", 0)
        unknown = sorted(set(nested) - {"env", "agent", "train"})
        if unknown:
            raise ValueError(f"unknown Experiment field(s): {', '.join(unknown)}")
        env = dict(nested.get("env", {}))
        agent = dict(nested.get("agent", {}))
        _check_fields(EnvConfig, env)
        _check_fields(AgentConfig, agent)
        _check_fields(TrainConfig, nested.get("train", {}))
        env["params"] = NeuronParams.from_dict(env.get("params", {}))
        env["extensions"] = Extensions.from_dict(env.get("extensions", {}))
        for name in ("train_contexts", "test_contexts"):
            if env.get(name) is not None:
                env[name] = Path(env[name])
        sizes = dict(agent.get("sizes", {}))
        _legacy_normalisation(sizes, env["params"])
        _check_fields(AgentSizes, sizes)
        agent["sizes"] = AgentSizes(
            **{key: tuple(value) if isinstance(value, list) else value
               for key, value in sizes.items()}
        )  # fmt: skip
        return cls(EnvConfig(**env), AgentConfig(**agent), TrainConfig(**nested.get("train", {})))

    def with_changes(
        self, changes: Mapping[str, Any] | None = None, /, **fields: Any
    ) -> Experiment:
        """A copy with some fields changed: ``changes`` maps field paths to values, as
        dotted names (``"env.n_train"``, ``"agent.sizes.lstm_hidden"``), nested dicts
        (``{"env": {"n_train": 20}}``) or a field's own name where it is unique in the
        tree, as in the flat config before the tree (``"n_train"``, ``"arch"``,
        ``"sizes": {...}``); keyword arguments are the latter
        (``with_changes(arch="drqn", seed=1)``). A changed ``env.id`` first takes its
        variant's settings (:meth:`EnvConfig.with_variant`), then the other changes."""
        leaves = _leaves(nest({**(changes or {}), **fields}))
        base = self
        env_id = leaves.pop(("env", "id"), None)
        if env_id is not None:
            base = dataclasses.replace(self, env=self.env.with_variant(env_id))
        values = base.to_dict()
        for path, value in leaves.items():
            node = values
            for key in path[:-1]:
                if not isinstance(node.get(key), dict):
                    raise ValueError(f"unknown config field {'.'.join(path)!r}")
                node = node[key]
            if path[-1] not in node:
                raise ValueError(f"unknown config field {'.'.join(path)!r}")
            node[path[-1]] = value
        return Experiment.from_dict(values)


LEGACY_FIELDS: dict[str, str] = {
    **{name: "env" for name in ("n_neurons", "episode_length", "n_train", "n_test", "n_val",
                                "context_seed", "train_contexts", "test_contexts")},
    **{name: "agent" for name in ("arch", "sizes")},
    **{f.name: "train" for f in dataclasses.fields(TrainConfig)},
}  # fmt: skip
"""Where each field of the flat config (before the tree) lives in the tree."""
SECTIONS = ("env", "agent", "train")


def nest(values: Mapping[str, Any]) -> dict[str, Any]:
    """A config dict in the tree's nested form: dotted keys (``"env.n_train"``) are
    split, and the flat names of the config before the tree (``"n_train"``, ``"arch"``,
    ``"seed"``) are put under their section; nested dicts are merged."""
    if not isinstance(values, Mapping):
        raise ValueError(f"a config is a JSON object, got {type(values).__name__}")
    nested: dict[str, Any] = {}
    for key, value in values.items():
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            value = dataclasses.asdict(value)  # a part of the tree: each of its fields
        if not isinstance(key, str):
            raise ValueError(f"config keys are strings, got {key!r}")
        path = key.split(".")
        if path[0] not in SECTIONS:
            if path[0] not in LEGACY_FIELDS:
                known = ", ".join(SECTIONS)
                raise ValueError(f"unknown config field {key!r} (the tree's sections: {known})")
            path = [LEGACY_FIELDS[path[0]], *path]
        node = nested
        for part in path[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"config field {key!r} conflicts with another one")
        if isinstance(value, Mapping) and isinstance(node.get(path[-1]), dict):
            node[path[-1]] = _merge(node[path[-1]], value)
        else:
            node[path[-1]] = dict(value) if isinstance(value, Mapping) else value
    return nested


def field_value(values: Mapping[str, Any], key: str) -> Any:
    """The value of a field in a nested config dict, named by its dotted path
    (``"env.n_train"``) or by its flat name from before the tree (``"n_train"``)."""
    path = key.split(".")
    if path[0] not in SECTIONS:
        if path[0] not in LEGACY_FIELDS:
            raise ValueError(f"unknown config field {key!r}")
        path = [LEGACY_FIELDS[path[0]], *path]
    node: Any = values
    for part in path:
        if not isinstance(node, Mapping) or part not in node:
            raise ValueError(f"unknown config field {key!r}")
        node = node[part]
    return node


def _merge(first: Mapping[str, Any], second: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(first)
    for key, value in second.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def _leaves(nested: Mapping[str, Any], prefix: tuple[str, ...] = ()) -> dict[tuple, Any]:
    """Field paths to values; a dict value is a set of field changes, not one value."""
    leaves: dict[tuple, Any] = {}
    for key, value in nested.items():
        if isinstance(value, Mapping):
            leaves.update(_leaves(value, (*prefix, key)))
        else:
            leaves[(*prefix, key)] = value
    return leaves


def _check_fields(kind: type, values: Mapping[str, Any]) -> None:
    if not isinstance(values, Mapping):
        raise ValueError(f"{kind.__name__} must be a JSON object, got {values!r}")
    known = {f.name for f in dataclasses.fields(kind)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {kind.__name__} field(s): {', '.join(unknown)}")


def _legacy_normalisation(sizes: dict[str, Any], params: NeuronParams) -> None:
    """Configs saved before the tree had the agent's voltage normalisation in its sizes;
    it is the environment's params now. Equal values are dropped; others cannot be
    represented and are refused."""
    for name in ("v_rest_mV", "v_threshold_mV"):
        if name in sizes:
            value = sizes.pop(name)
            if value != getattr(params, name):
                raise ValueError(
                    f"sizes.{name} = {value} differs from the environment's params.{name} = "
                    f"{getattr(params, name)}: the agent's input is normalised with the "
                    "environment's params now, so this run cannot be rebuilt as it was"
                )
