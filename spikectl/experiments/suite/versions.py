"""Suite versions as data: each version's tasks, set size, episode length, environment
seed and the checksums of its sets, in a registry of versions.

A version is registered once (:func:`register_suite_version`) and its tasks one line
each (:func:`register_task`). A released version is ``frozen``: its tasks are what its
scores were measured on, so a new task goes into a new version, which lives beside it
(results of two versions do not compare).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from spikectl.envs.registration import registered_kwargs
from spikectl.neuron.extensions import Extensions
from spikectl.registry import Registry, RegistryError

SPLITS = ("train", "validation", "test")
DEFAULT_SUITE = 1
"""The version ``spikectl benchmark`` plays without ``--suite``."""


@dataclass(frozen=True)
class Task:
    """One task of a suite version: a registered environment, its overrides, a network
    size, the seed of its sets and their pinned checksums."""

    name: str
    """The task's name on the command line and in tables."""
    env_id: str
    """The registered environment id the task is a setting of."""
    overrides: Mapping[str, Any]
    """Extension fields changed from the registered environment's (JSON-ready)."""
    n_neurons: int
    """Network size n."""
    seed: int
    """The generation seed of make_splits."""
    description: str
    """One line for tables and docs."""
    checksums: Mapping[str, str] = field(default_factory=dict)
    """split -> :func:`~spikectl.experiments.suite.protocol.suite_checksum` of its set,
    pinned: a generator that draws other networks is refused, never scored."""

    @property
    def extensions(self) -> Extensions:
        """Every extension of the task: the registered environment's, then the overrides."""
        registered = registered_kwargs(self.env_id).get("extensions", {})
        return Extensions.coerce({**registered, **self.overrides})

    @property
    def n_observed(self) -> int:
        """k, the neurons an agent sees (n less the hidden ones)."""
        return self.n_neurons - self.extensions.hidden_count(self.n_neurons)


@dataclass(frozen=True, eq=False)
class SuiteVersion:
    """One version of the suite: the protocol's sizes and seed, and its tasks (in table
    order). ``frozen`` refuses new tasks: the version's scores are published."""

    number: int
    set_size: int = 100
    """Contexts in each of a task's train, validation and test sets."""
    episode_length: int = 60
    """Steps per episode (the paper's)."""
    env_seed: int = 0
    """Seed of the environments' generators in the protocol (noise, release, background)."""
    frozen: bool = False
    tasks: Registry[Task] = field(default_factory=lambda: Registry("task"))

    def task(self, name: object) -> Task:
        """The task called ``name``; an unknown name is one RegistryError line listing
        this version's tasks."""
        if name not in self.tasks:
            elsewhere = [v for v in SUITES if name in SUITES.load(v).tasks]
            hint = f" ({name!r} is a task of suite v{elsewhere[0]})" if elsewhere else ""
            raise RegistryError(
                f"unknown task {name!r} of benchmark suite v{self.number}{hint}; tasks: "
                f"{', '.join(self.tasks)}"
            )
        return self.tasks.load(name)

    def names(self) -> tuple[str, ...]:
        """The tasks' names in table order."""
        return self.tasks.names()


SUITES: Registry[SuiteVersion] = Registry("benchmark suite version")
"""Version number (as a string: ``"1"``) -> :class:`SuiteVersion`."""


def register_suite_version(version: SuiteVersion) -> SuiteVersion:
    """Register a suite version beside the others (its tasks: :func:`register_task`)."""
    if not isinstance(version, SuiteVersion):
        raise RegistryError(f"expected a SuiteVersion, got {type(version).__name__}")
    return SUITES.register(str(version.number), version)


def suite_version(number: object = DEFAULT_SUITE) -> SuiteVersion:
    """The registered suite version ``number``; an unknown one is one RegistryError line
    listing the versions there are."""
    if isinstance(number, bool) or not isinstance(number, int):
        raise RegistryError(f"a suite version is an integer, got {number!r}")
    return SUITES.load(str(number))


def register_task(task: Task, version: int) -> Task:
    """Add ``task`` to suite ``version`` (registered, not frozen); its checksums must pin
    the three sets (:data:`SPLITS`)."""
    suite = suite_version(version)
    if suite.frozen and task.name not in suite.tasks:
        raise RegistryError(
            f"benchmark suite v{suite.number} is frozen (its scores are published): a new "
            f"task such as {task.name!r} goes into a new suite version"
        )
    missing = [split for split in SPLITS if split not in task.checksums]
    if missing:
        raise RegistryError(f"task {task.name!r} pins no checksum for {', '.join(missing)}")
    registered_kwargs(task.env_id)  # an unknown environment id is refused here
    return suite.tasks.register(task.name, task)


def task(name: object, version: int = DEFAULT_SUITE) -> Task:
    """The task called ``name`` of suite ``version``; an unknown name is one line listing
    the version's tasks."""
    return suite_version(version).task(name)
