"""The registry of learners: one entry per learner, read by everything that must know
them (the config tree and config.json, the training loop, the presets, the command line,
sweeps and checkpoints).

An entry is a learner's config class (a frozen dataclass whose ``name`` is the learner's
name in config.json), where its implementation lives (a class, or ``"module:Class"``
imported when a run starts, so that the config tree never imports Torch), its stacked
form if it has one, and its presets with their help. Gymnasium's environment registry is
the model: ``register`` once, then look up by name.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Preset:
    """A named instance of the config tree for ``spikectl train NAME``: ``build`` makes it
    from the base presets (``paper``, ``quick``, ``smoke`` by name), ``help`` is its line
    in ``spikectl train --help`` and the docs' preset table."""

    name: str
    help: str
    build: Callable[[Mapping[str, Any]], Any]


@dataclass(frozen=True)
class LearnerEntry:
    """One learner: its config class, its implementation (one seed's
    :class:`~spikectl.training.learners.protocol.Learner`, made as
    ``learner(config, train_set, rng)``), its optional stacked group (made as
    ``stacked(configs, train_sets, rngs)``) and its presets."""

    config: type
    learner: type | str
    stacked: type | str | None = None
    presets: tuple[Preset, ...] = ()

    @property
    def name(self) -> str:
        return self.config.name

    def learner_class(self) -> type:
        return _load(self.learner)

    def stacked_class(self) -> type | None:
        return None if self.stacked is None else _load(self.stacked)


_LEARNERS: dict[str, LearnerEntry] = {}


def register(
    config: type,
    learner: type | str,
    *,
    stacked: type | str | None = None,
    presets: tuple[Preset, ...] = (),
) -> LearnerEntry:
    """Register a learner under ``config.name``; the same entry again is a no-op, another
    entry under a taken name a ValueError."""
    name = getattr(config, "name", None)
    if not dataclasses.is_dataclass(config) or not isinstance(name, str) or not name:
        raise TypeError(
            f"a learner's config must be a dataclass with a class attribute name, got {config!r}"
        )
    if not callable(getattr(config, "check_episode_length", None)):
        raise TypeError(f"{config.__name__} lacks check_episode_length(episode_length)")
    entry = LearnerEntry(config, learner, stacked, tuple(presets))
    if _LEARNERS.get(name, entry) != entry:
        raise ValueError(f"a learner named {name!r} is already registered")
    _LEARNERS[name] = entry
    return entry


def learner_entries() -> tuple[LearnerEntry, ...]:
    """Every registered learner, in the order of registration."""
    return tuple(_LEARNERS.values())


def learner_entry(name: object) -> LearnerEntry:
    """The entry of the learner called ``name``; a one-line error for another name."""
    if not isinstance(name, str) or name not in _LEARNERS:
        raise ValueError(
            f"learner.name: unknown learner {name!r}; this spikectl has "
            f"{', '.join(sorted(_LEARNERS))}"
        )
    return _LEARNERS[name]


def learner_config_type(name: object) -> type:
    """The config class of the learner called ``name``."""
    return learner_entry(name).config


def learner_configs() -> tuple[type, ...]:
    """Every registered learner's config class."""
    return tuple(entry.config for entry in _LEARNERS.values())


def _load(target: type | str) -> type:
    if not isinstance(target, str):
        return target
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)
