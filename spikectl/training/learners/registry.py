"""The registry of learners: one entry per learner, read by everything that must know
them (the config tree and config.json, the training loop, the presets, the command line,
sweeps and checkpoints).

An entry is a learner's config class (a frozen dataclass whose ``name`` is the learner's
name in config.json), where its implementation lives (a class, or ``"module:Class"``
imported when a run starts, so that the config tree never imports Torch), its stacked
form if it has one, and its presets with their help. The entries live in a
:class:`spikectl.registry.Registry` (``LEARNERS``), the one registry mechanism.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from spikectl.registry import Registry, RegistryError, load_target


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
        return load_target(self.learner)

    def stacked_class(self) -> type | None:
        return None if self.stacked is None else load_target(self.stacked)


LEARNERS: Registry[LearnerEntry] = Registry("learner")


def register(
    config: type,
    learner: type | str,
    *,
    stacked: type | str | None = None,
    presets: tuple[Preset, ...] = (),
) -> LearnerEntry:
    """Register a learner under ``config.name``; the same entry again is a no-op, another
    entry under a taken name a RegistryError (a ValueError)."""
    name = getattr(config, "name", None)
    if not dataclasses.is_dataclass(config) or not isinstance(name, str) or not name:
        raise TypeError(
            f"a learner's config must be a dataclass with a class attribute name, got {config!r}"
        )
    if not callable(getattr(config, "check_episode_length", None)):
        raise TypeError(f"{config.__name__} lacks check_episode_length(episode_length)")
    entry = LearnerEntry(config, learner, stacked, tuple(presets))
    LEARNERS.register(name, entry)
    return entry


def learner_entries() -> tuple[LearnerEntry, ...]:
    """Every registered learner, in the order of registration."""
    return tuple(LEARNERS.load(name) for name in LEARNERS)


def learner_entry(name: object) -> LearnerEntry:
    """The entry of the learner called ``name``; a one-line RegistryError (a ValueError)
    naming the field and the registered learners for another name."""
    try:
        return LEARNERS.load(name)
    except RegistryError as error:
        raise RegistryError(f"learner.name: {error}") from None


def learner_config_type(name: object) -> type:
    """The config class of the learner called ``name``."""
    return learner_entry(name).config


def learner_configs() -> tuple[type, ...]:
    """Every registered learner's config class."""
    return tuple(entry.config for entry in learner_entries())
