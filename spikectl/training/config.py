"""The typed configuration tree of a training run and its presets (SPEC 5, paper Table 2).

One tree is the single source of truth for a run: what it trains on, what it trains
and how::

    Experiment(
        env=EnvConfig(id, n_neurons, episode_length, n_train, n_test, n_val, context_seed,
                      train_contexts, test_contexts, params=NeuronParams(...),
                      extensions=Extensions(...)),
        agent=AgentConfig(arch, sizes=AgentSizes(...)),
        train=TrainConfig(seed, total_env_steps, num_envs, eval_every_episodes, ..., device),
        learner=DQNConfig(updates_per_round, batch_size, learning_rate, gamma, ...),
    )

Every part is a frozen dataclass with a one-line docstring per field; tyro turns the
tree into the command line (``spikectl train``), ``config.json`` stores it
(:meth:`Experiment.to_dict`) and everything that rebuilds a run (resume, evaluate,
sweep, plot, seed groups) reads it back (:meth:`Experiment.from_dict`, which also reads
the configs earlier versions saved: ``spikectl.training.config_migration``). ``train`` is
the run around any learner; ``learner`` is the algorithm, a config class per learner
(``spikectl.training.learners``), named in config.json. The agent's voltage normalisation is
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
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import tyro

from spikectl.agents import ARCHITECTURES, AgentSizes, Architecture
from spikectl.agents.sizes import inputs_from_flags
from spikectl.config_errors import ConfigError, check_field_types, check_int
from spikectl.contexts import MAX_EPISODE_LENGTH, MAX_N_NEURONS
from spikectl.envs.registration import ENV_ID
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.training.config_migration import (
    check_fields,
    drop_removed_fields,
    field_value,
    leaf_paths,
    legacy_normalisation,
    migrate,
    nest,
)
from spikectl.training.learners import (
    DQNConfig,
    LearnerConfig,
    learner_config_type,
    learner_configs,
)
from spikectl.training.variants import flat_settings, split_settings, variant_settings

MAX_TORCH_THREADS = 256
"""More Torch threads than any one machine spikectl runs on has cores (a typo such as
100000 made OpenBLAS fail to start its threads and the run hang)."""

SECTION_PATHS = (("env",), ("env", "params"), ("env", "extensions"), ("agent",),
                 ("agent", "sizes"), ("train",), ("learner",))  # fmt: skip
"""The tables of a saved config (what must be a JSON object, not a value)."""

__all__ = ["AgentConfig", "EnvConfig", "Experiment", "TrainConfig", "field_value", "nest"]


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
            raise ConfigError(
                "id", f"must be a registered environment id, got {self.id!r}", label="env"
            )
        check_field_types(self)
        check_int("n_neurons", self.n_neurons, 2, MAX_N_NEURONS,
                   f"an integer in 2..{MAX_N_NEURONS} (MAX_N_NEURONS)")  # fmt: skip
        check_int("episode_length", self.episode_length, 2, MAX_EPISODE_LENGTH,
                   f"an integer in 2..{MAX_EPISODE_LENGTH} (MAX_EPISODE_LENGTH)")  # fmt: skip
        for name in ("n_train", "n_test"):
            check_int(name, getattr(self, name), 1, what="a positive integer")
        check_int("n_val", self.n_val, 0, what="a non-negative integer")
        check_int("context_seed", self.context_seed, 0, 2**63 - 1, "an integer in 0..2**63 - 1")
        for name, kind in (("params", NeuronParams), ("extensions", Extensions)):
            if not isinstance(getattr(self, name), kind):
                raise ConfigError(name, f"must be a {kind.__name__}, got {getattr(self, name)!r}")
        self._check_variant()
        try:
            self.extensions.hidden_count(self.n_neurons)  # at least 2 observable neurons
        except ValueError as error:
            name = "hidden_neurons" if self.extensions.hidden_neurons else "hidden_fraction"
            raise ConfigError(
                ("extensions", name), str(error), label=f"extensions.{name}", sep=": "
            ) from None

    def _settings(self) -> dict[str, Any]:
        sizes = {"n_neurons": self.n_neurons, "episode_length": self.episode_length}
        return flat_settings(sizes, self.params, self.extensions)

    def _check_variant(self) -> None:
        """Refuse a setting the variant changes that is still the base environment's:
        ``EnvConfig(id=variant)`` alone would otherwise train without the variant."""
        base, mine = _base_settings(), self._settings()
        for name, value in variant_settings(self.id).items():
            if mine[name] == base[name] != value:
                raise ConfigError(
                    "id",
                    f"{self.id} sets {name} = {value!r}, but this config has the base "
                    f"environment's {mine[name]!r}: take the variant's settings with "
                    f"EnvConfig.with_variant / with_changes({{'env.id': ...}}), or use "
                    f"{ENV_ID} to leave that setting at the paper's",
                    label="env",
                    sep=": ",
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
    init_from: Path | None = None
    """Start the Q-network from these weights instead of a fresh initialisation: a
    model file (model.pt, best_model.pt) or a run directory (its best_model.pt). The
    architecture and sizes must match; the per-neuron architectures (ddrqn, tdrqn) take
    weights trained at another number of neurons (a curriculum over network sizes)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        if self.arch not in ARCHITECTURES:
            raise ConfigError("arch", f"must be one of {ARCHITECTURES}, got {self.arch!r}")
        if not isinstance(self.sizes, AgentSizes):
            raise ConfigError("sizes", f"must be an AgentSizes, got {self.sizes!r}")
        try:
            self.sizes.check_architecture(self.arch)
        except ConfigError as error:
            raise error.within("sizes") from None


@dataclass(frozen=True)
class TrainConfig:
    """The run around any learner: its seed, length, collection width, evaluations,
    checkpoints and machine (the learner's own settings are ``Experiment.learner``)."""

    seed: int = 0
    """Seed of the network initialisation, exploration, context choice and replay sampling."""
    total_env_steps: int = 1_000_000
    """Environment steps to train for (episodes = total_env_steps / episode_length)."""
    num_envs: int = 5
    """Episodes collected in parallel per round (one vector-env batch)."""
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
    cuda_graphs: bool = True
    """Replay a stacked group's update and acting step as CUDA graphs (--stacked on CUDA)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("total_env_steps", "num_envs", "eval_every_episodes",
                     "checkpoint_every_episodes"):  # fmt: skip
            check_int(name, getattr(self, name), 1, what="a positive integer")
        check_int("torch_threads", self.torch_threads, 0, MAX_TORCH_THREADS,
                  f"an integer in 0..{MAX_TORCH_THREADS} (0: PyTorch's default)")  # fmt: skip
        check_int("seed", self.seed, 0, 2**63 - 1, "an integer in 0..2**63 - 1")
        if not isinstance(self.device, str) or not self.device:
            raise ConfigError(
                "device", f"must be a string such as cpu or cuda, got {self.device!r}"
            )
        for name in ("progress", "cuda_graphs"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(name, f"must be true or false, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class Experiment:
    """One training run: the environment, the agent, the run and the learner."""

    env: Annotated[EnvConfig, tyro.conf.arg(name="")] = field(default_factory=EnvConfig)
    """What the agent trains on."""
    agent: Annotated[AgentConfig, tyro.conf.arg(name="")] = field(default_factory=AgentConfig)
    """The network."""
    train: Annotated[TrainConfig, tyro.conf.arg(name="")] = field(default_factory=TrainConfig)
    """The run: seed, length, evaluations, checkpoints, machine."""
    learner: Annotated[LearnerConfig, tyro.conf.arg(name=""), tyro.conf.AvoidSubcommands] = field(
        default_factory=DQNConfig
    )
    """The learning algorithm, chosen by its config's type (``learner.name`` in config.json)."""

    def __post_init__(self) -> None:
        for name, kind in (("env", EnvConfig), ("agent", AgentConfig), ("train", TrainConfig),
                           ("learner", learner_configs())):  # fmt: skip
            if not isinstance(getattr(self, name), kind):
                value = getattr(self, name)
                raise ConfigError(name, f"must be a {_kind_name(kind)}, got {value!r}")
        sizes = self.agent.sizes
        length, train = self.env.episode_length, self.train
        try:
            check_agent = getattr(self.learner, "check_agent", None)
            if check_agent is not None:  # a learner that builds on the agent's network
                check_agent(self.agent.arch, sizes)
            self.learner.check_episode_length(length)
        except ConfigError as error:
            raise error.within("learner") from None
        if train.total_env_steps < length * train.num_envs:
            raise ConfigError(
                ("train", "total_env_steps"),
                f"({train.total_env_steps}) is less than one round of "
                f"num_envs x episode_length ({train.num_envs * length})",
            )

    @property
    def total_episodes(self) -> int:
        """Whole rounds of num_envs episodes that fit in total_env_steps."""
        rounds = self.train.total_env_steps // (self.env.episode_length * self.train.num_envs)
        return rounds * self.train.num_envs

    def with_seed(self, seed: int) -> Experiment:
        """The same experiment with another training seed."""
        return dataclasses.replace(self, train=dataclasses.replace(self.train, seed=seed))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict: {"env": {..., "params": {...}, "extensions": {...}},
        "agent": {"arch": ..., "sizes": {...}}, "train": {...}, "learner": {"name": "dqn",
        ...}} (paths as strings)."""
        values = {
            name: dataclasses.asdict(getattr(self, name)) for name in ("env", "agent", "train")
        }
        values["learner"] = {"name": self.learner.name, **dataclasses.asdict(self.learner)}
        for name in ("train_contexts", "test_contexts"):
            if values["env"][name] is not None:
                values["env"][name] = str(values["env"][name])
        if values["agent"]["init_from"] is not None:
            values["agent"]["init_from"] = str(values["agent"]["init_from"])
        values["agent"]["sizes"] = {
            key: list(value) if isinstance(value, tuple) else value
            for key, value in values["agent"]["sizes"].items()
        }
        return values

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Experiment:
        """Inverse of :meth:`to_dict`; also reads the configs of runs saved by earlier
        versions (``spikectl.training.config_migration``). Unknown fields are an error."""
        nested = migrate(values)
        for path in SECTION_PATHS:
            section = nested
            for key in path:
                section = section.get(key, {}) if isinstance(section, Mapping) else {}
            if not isinstance(section, Mapping):
                raise ConfigError(
                    path, f"is a section of the config (a table of fields), got {section!r}"
                )
        env = dict(nested.get("env", {}))
        agent = dict(nested.get("agent", {}))
        learner = dict(nested.get("learner", {}))
        learner_type = learner_config_type(learner.pop("name", DQNConfig.name))
        drop_removed_fields(learner_type, "learner", learner)
        for kind, section, part in ((EnvConfig, "env", env), (AgentConfig, "agent", agent),
                                    (TrainConfig, "train", nested.get("train", {})),
                                    (learner_type, "learner", learner)):  # fmt: skip
            check_fields(kind, section, part)
        for name, kind in (("params", NeuronParams), ("extensions", Extensions)):
            try:
                env[name] = kind.from_dict(env.get(name, {}))
            except ConfigError as error:
                raise error.within("env", name) from None
        for name in ("train_contexts", "test_contexts"):
            if isinstance(env.get(name), str):
                env[name] = Path(env[name])
        if isinstance(agent.get("init_from"), str):
            agent["init_from"] = Path(agent["init_from"])
        sizes = dict(agent.get("sizes", {}))
        legacy_normalisation(sizes, env["params"])
        drop_removed_fields(AgentSizes, "agent.sizes", sizes)
        inputs_from_flags(sizes)
        check_fields(AgentSizes, "agent.sizes", sizes)
        try:
            agent["sizes"] = AgentSizes(
                **{key: tuple(value) if isinstance(value, list) else value
                   for key, value in sizes.items()}
            )  # fmt: skip
        except ConfigError as error:
            raise error.within("agent", "sizes") from None
        parts = {}
        for name, kind, part in (("env", EnvConfig, env), ("agent", AgentConfig, agent),
                                 ("train", TrainConfig, nested.get("train", {})),
                                 ("learner", learner_type, learner)):  # fmt: skip
            if name == "learner":  # a field added since the config was saved: as it ran
                saved_without = getattr(learner_type, "fields_saved_without", None)
                for key, value in (saved_without(parts["env"]) if saved_without else {}).items():
                    part.setdefault(key, value)
            try:
                parts[name] = kind(**part)
            except ConfigError as error:
                raise error.within(name) from None
        return cls(**parts)

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
        leaves = leaf_paths(nest({**(changes or {}), **fields}))
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
            if isinstance(node[path[-1]], dict) and not isinstance(value, Mapping):
                raise ValueError(
                    f"{'.'.join(path)} is a section of the config (a table of fields), not "
                    f"a value: got {value!r}"
                )
            node[path[-1]] = value
        return Experiment.from_dict(values)


def _kind_name(kind: type | tuple[type, ...]) -> str:
    return " or ".join(k.__name__ for k in kind) if isinstance(kind, tuple) else kind.__name__
