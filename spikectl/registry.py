"""One registry mechanism for every kind of plug-in: learners, controllers, suite tasks
and environment variants.

Gymnasium's environment registry is the model: ``register`` once under a name, then look
up by name. A :class:`Registry` holds entries of one kind; the same entry registered again
under its name is a no-op (a module may be imported twice), another entry under a taken
name is a :class:`RegistryError`, and an unknown name is a :class:`RegistryError` whose one
line lists the names there are. An entry may be given as ``"module:attribute"``, imported
only when it is looked up, so that registering costs no import (no work at import time).

```python
from spikectl.registry import Registry

CONTROLLERS = Registry("controller")
CONTROLLERS.register("do-nothing", "spikectl.envs.controller:DoNothing")
CONTROLLERS.load("do-nothing")  # the class, imported now
```
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from typing import Any, Generic, TypeVar

T = TypeVar("T")


class RegistryError(ValueError):
    """A name registered twice with different entries, or a name nobody registered."""


class Registry(Generic[T]):
    """Named entries of one ``kind`` (its word in messages: "learner", "controller", ...),
    in the order of registration."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._entries: dict[str, T | str] = {}

    def register(self, name: str, entry: T | str) -> T | str:
        """Register ``entry`` (an object, or ``"module:attribute"`` imported on
        :meth:`load`) under ``name``; returns it, so that it can decorate a class."""
        if not isinstance(name, str) or not name:
            raise RegistryError(f"a {self.kind}'s name must be a non-empty string, got {name!r}")
        taken = self._entries.get(name, entry)
        if taken != entry:
            raise RegistryError(
                f"a {self.kind} named {name!r} is already registered ({_describe(taken)}); "
                f"{_describe(entry)} needs another name"
            )
        self._entries[name] = entry
        return entry

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def names(self) -> tuple[str, ...]:
        """Every registered name, in the order of registration."""
        return tuple(self._entries)

    def entry(self, name: object) -> T | str:
        """The entry under ``name`` as registered (a ``"module:attribute"`` string stays
        one); a one-line :class:`RegistryError` naming the registered ones otherwise."""
        if not isinstance(name, str) or name not in self._entries:
            known = ", ".join(self._entries) or "none"
            raise RegistryError(f"unknown {self.kind} {name!r}; this spikectl has {known}")
        return self._entries[name]

    def load(self, name: object) -> T:
        """The entry under ``name``, a ``"module:attribute"`` string imported now."""
        return load_target(self.entry(name))


def load_target(target: Any) -> Any:
    """``target`` itself, or the attribute a ``"module:attribute"`` string names."""
    if not isinstance(target, str):
        return target
    module, _, attribute = target.partition(":")
    if not attribute:
        raise RegistryError(f"{target!r} is not of the form 'module:attribute'")
    return getattr(importlib.import_module(module), attribute)


def _describe(entry: Any) -> str:
    return entry if isinstance(entry, str) else getattr(entry, "__qualname__", repr(entry))
