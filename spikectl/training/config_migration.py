"""Configs as earlier versions of spikectl saved them, read into today's tree.

Three generations of config.json exist:

1. *flat* (before the tree): ``{"n_train": 100, "arch": "tdrqn", "seed": 0, ...}``, with
   no validation split (``n_val`` 0) and the agent's voltage normalisation in its sizes;
2. *the tree with the learner inside ``train``*: ``{"env": ..., "agent": ..., "train":
   {"seed": 0, "learning_rate": ..., "gamma": ...}}``;
3. *today's*: ``train`` holds the run around any learner and ``learner`` the learning
   algorithm, chosen by name: ``"learner": {"name": "dqn", "learning_rate": ...}``.

:func:`migrate` turns any of them into the third's nested form; the same field names
work in sweep files and ``Experiment.with_changes`` (``"learning_rate"``,
``"train.learning_rate"`` and ``"learner.learning_rate"`` are one field).

Kept because docs/training.md promises it: ``Experiment.from_dict`` reads every
generation, and every committed run under docs/results/ loads. The checks of a saved
section (:func:`check_fields`, :func:`drop_removed_fields`) are here too: a saved config
names only fields the tree has, or fields it dropped at the value runs ran as today's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from spikectl.config_errors import ConfigError
from spikectl.neuron.params import NeuronParams
from spikectl.training.learners import DQNConfig

SECTIONS = ("env", "agent", "train", "learner")
RUN_FIELDS = ("seed", "total_env_steps", "num_envs", "eval_every_episodes",
              "checkpoint_every_episodes", "device", "torch_threads", "progress",
              "cuda_graphs")  # fmt: skip
"""The fields of today's ``train`` section (the run); every other field of the old
``train`` section is the learner's."""
LEARNER_FIELDS = tuple(field.name for field in dataclasses.fields(DQNConfig))
LEGACY_FIELDS: dict[str, str] = {
    **{name: "env" for name in ("n_neurons", "episode_length", "n_train", "n_test", "n_val",
                                "context_seed", "train_contexts", "test_contexts")},
    **{name: "agent" for name in ("arch", "sizes", "init_from")},
    **{name: "train" for name in RUN_FIELDS},
    **{name: "learner" for name in LEARNER_FIELDS},
}  # fmt: skip
"""Where each field of the flat config (before the tree) lives in the tree, and the agent's
fields added since, which ``with_changes`` also takes by their own name."""


def field_path(key: str) -> list[str]:
    """A field's path in today's tree from any name for it: dotted (``"env.n_train"``),
    flat (``"n_train"``) or the learner's settings under ``train`` (``"train.gamma"``)."""
    if not isinstance(key, str):
        raise ValueError(f"config keys are strings, got {key!r}")
    path = key.split(".")
    if path[0] not in SECTIONS:
        if path[0] not in LEGACY_FIELDS:
            known = ", ".join(SECTIONS)
            raise ValueError(f"unknown config field {key!r} (the tree's sections: {known})")
        path = [LEGACY_FIELDS[path[0]], *path]
    if path[0] == "train" and len(path) > 1 and path[1] in LEARNER_FIELDS:
        path = ["learner", *path[1:]]
    return path


def nest(values: Mapping[str, Any]) -> dict[str, Any]:
    """A config dict in the tree's nested form: dotted keys are split, flat and moved
    names are put where :func:`field_path` says, nested dicts are merged."""
    if not isinstance(values, Mapping):
        raise ValueError(f"a config is a JSON object, got {type(values).__name__}")
    nested: dict[str, Any] = {}
    for key, value in values.items():
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            value = dataclasses.asdict(value)  # a part of the tree: each of its fields
        if key in SECTIONS and isinstance(value, Mapping):
            for inner, item in value.items():  # an old train section: some are the learner's
                _put(nested, field_path(f"{key}.{inner}"), item, f"{key}.{inner}")
            continue
        _put(nested, field_path(key), value, key)
    return nested


def _put(nested: dict[str, Any], path: list[str], value: Any, key: str) -> None:
    node = nested
    for part in path[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ValueError(f"config field {key!r} conflicts with another one")
    if isinstance(value, Mapping) and isinstance(node.get(path[-1]), dict):
        node[path[-1]] = _merge(node[path[-1]], value)
    else:
        node[path[-1]] = dict(value) if isinstance(value, Mapping) else value


def migrate(values: Mapping[str, Any]) -> dict[str, Any]:
    """A saved config of any generation in today's nested form (see the module's doc)."""
    nested = nest(values)
    if isinstance(values, Mapping) and not any(key in SECTIONS for key in values):
        # A flat config of a run saved before the validation split existed had none.
        nested.setdefault("env", {}).setdefault("n_val", 0)
    return nested


def field_value(values: Mapping[str, Any], key: str) -> Any:
    """The value of a field in a nested config dict, named by its dotted path
    (``"env.n_train"``) or by its flat name from before the tree (``"n_train"``)."""
    node: Any = values
    for part in field_path(key):
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


def leaf_paths(nested: Mapping[str, Any], prefix: tuple[str, ...] = ()) -> dict[tuple, Any]:
    """Field paths to values; a dict value is a set of field changes, not one value."""
    leaves: dict[tuple, Any] = {}
    for key, value in nested.items():
        if isinstance(value, Mapping):
            leaves.update(leaf_paths(value, (*prefix, key)))
        else:
            leaves[(*prefix, key)] = value
    return leaves


def legacy_normalisation(sizes: dict[str, Any], params: NeuronParams) -> None:
    """Configs saved before the tree had the agent's voltage normalisation in its sizes;
    it is the environment's params now. Equal values are dropped; others cannot be
    represented and are refused."""
    for name in ("v_rest_mV", "v_threshold_mV"):
        if name in sizes:
            value = sizes.pop(name)
            if value != getattr(params, name):
                raise ConfigError(
                    ("agent", "sizes", name),
                    f"= {value} differs from the environment's params.{name} = "
                    f"{getattr(params, name)}: the agent's input is normalised with the "
                    "environment's params now, so this run cannot be rebuilt as it was",
                    label=f"sizes.{name}",
                )


def drop_removed_fields(kind: type, section: str, values: dict[str, Any]) -> None:
    """Drop from a saved config section the fields spikectl no longer has
    (``kind.removed_fields``: name → (the value under which a run ran as today's, why
    the field went)) where they hold that value; any other value cannot be rebuilt and
    is refused in one line."""
    for name, (value_now, why) in getattr(kind, "removed_fields", {}).items():
        if name in values and values.pop(name) != value_now:
            raise ConfigError(
                (*section.split("."), name),
                f"is no longer in spikectl ({why}); a run with it cannot be rebuilt",
            )


def check_fields(kind: type, section: str, values: Mapping[str, Any]) -> None:
    """Refuse a config section that is not a mapping or names fields ``kind`` lacks."""
    if not isinstance(values, Mapping):
        raise ConfigError(tuple(section.split(".")), f"must be a JSON object, got {values!r}")
    known = {f.name for f in dataclasses.fields(kind)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {kind.__name__} field(s): {', '.join(unknown)}")
