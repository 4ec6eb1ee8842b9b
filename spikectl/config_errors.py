"""Config errors as data: a validation error that carries the path of the field it is about.

Every config of spikectl (the training tree, NeuronParams, Extensions, the network sizes)
refuses a bad value with a :class:`ConfigError`. Its message reads as before
(``"gamma must lie in [0, 1], got 2"``: the field's name, then what is wrong), and its
``path`` names the field within the whole tree (``("learner", "gamma")``), so that the
command line can name the flag by a lookup (``spikectl.cli``), never by reading the text.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import types
import typing
from typing import Any, Literal, Union


class ConfigError(ValueError):
    """A config field with a bad value; ``path`` is the field's place in the tree.

    The message is ``label``, ``sep`` and ``problem``: by default the field's own name and
    a space (``"gamma must lie in [0, 1], got 2"``). ``label`` keeps a message that names
    the field otherwise as it was (``"AgentSizes.lstm_hidden ..."``; ``""``: the problem
    alone); :meth:`naming` puts another name, such as the field's flag, in its place.
    """

    def __init__(
        self,
        field: str | tuple[str, ...],
        problem: str,
        *,
        label: str | None = None,
        sep: str = " ",
    ) -> None:
        self.path: tuple[str, ...] = (field,) if isinstance(field, str) else tuple(field)
        self.problem = problem
        self.label = self.path[-1] if label is None else label
        self.sep = sep
        super().__init__(f"{self.label}{sep}{problem}" if self.label else problem)

    def within(self, *prefix: str) -> ConfigError:
        """The same error, its path lengthened by the enclosing fields ``prefix``."""
        error = type(self)((*prefix, *self.path), self.problem, label=self.label, sep=self.sep)
        return error.with_traceback(None)

    def naming(self, name: str) -> str:
        """The message with ``name`` (a flag, say) for the field:
        ``naming("--gamma")`` is ``"--gamma must lie in [0, 1], got 2"``."""
        return f"{name}{self.sep if self.label else ': '}{self.problem}"

    def __reduce__(self) -> tuple[Any, ...]:
        # Pickled whole (e.g. from a sweep's worker process), not from the message alone.
        return _config_error, (self.path, self.problem, self.label, self.sep, type(self))

    @property
    def dotted(self) -> str:
        """The field's dotted path, e.g. ``learner.gamma``."""
        return ".".join(self.path)


class MissingExtraError(ImportError):
    """An optional dependency a feature needs is not installed; the message names the
    pip extra that installs it (``pip install "spikectl[ray]"``)."""


class ConfigTypeError(ConfigError, TypeError):
    """A config field whose value has the wrong type (a string for a number, say): a
    :class:`ConfigError` (the command line reports it in one line naming the flag) and a
    ``TypeError``."""


def _config_error(
    path: tuple[str, ...], problem: str, label: str, sep: str, kind: type = ConfigError
) -> ConfigError:
    return kind(path, problem, label=label, sep=sep)


def check_int(name: str, value: Any, low: int, high: int | None = None, what: str = "") -> None:
    """Refuse ``value`` for field ``name`` unless it is an int (not a bool) in [low, high]."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < low
        or (high is not None and value > high)
    ):
        raise ConfigError(name, f"must be {what}, got {value!r}")


def check_field_types(config: Any) -> None:
    """Refuse the first field of the dataclass instance ``config`` whose value is not of its
    declared type, in one line naming the field (a :class:`ConfigTypeError`): the one type
    check of every part of the config tree, whatever built it (the command line, a sweep
    file, ``with_changes``, Python). ``int`` is an integer (not a bool), ``float`` any real
    number (not a bool); ``X | None``, ``Literal``, ``tuple[X, ...]``, paths and dataclass
    types are followed; ranges are the part's own ``__post_init__``'s to check."""
    hints = _field_types(type(config))
    for field in dataclasses.fields(config):
        value, expected = getattr(config, field.name), hints[field.name]
        if not _matches(value, expected):
            raise ConfigTypeError(field.name, f"must be {_describe(expected)}, got {value!r}")


@functools.cache
def _field_types(kind: type) -> dict[str, Any]:
    return typing.get_type_hints(kind)


def _arms(expected: Any) -> tuple[Any, ...] | None:
    origin = typing.get_origin(expected)
    return typing.get_args(expected) if origin in (Union, types.UnionType) else None


def _matches(value: Any, expected: Any) -> bool:
    arms = _arms(expected)
    if arms is not None:
        return any(_matches(value, arm) for arm in arms)
    origin, args = typing.get_origin(expected), typing.get_args(expected)
    if expected is type(None):
        return value is None
    if origin is Literal:
        return any(type(value) is type(arg) and value == arg for arg in args)
    if expected is bool:
        return isinstance(value, bool)
    if expected is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if expected is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if expected is str:
        return isinstance(value, str)
    if origin is tuple:
        if not isinstance(value, tuple):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_matches(item, args[0]) for item in value)
        return len(value) == len(args) and all(map(_matches, value, args))
    if isinstance(expected, type) and issubclass(expected, os.PathLike):
        return isinstance(value, (str, os.PathLike))
    if isinstance(expected, type) and dataclasses.is_dataclass(expected):
        return isinstance(value, expected)
    return True  # Any, or a type the parts check themselves


def _describe(expected: Any) -> str:
    arms = _arms(expected)
    if arms is not None:
        return " or ".join(_describe(arm) for arm in arms)
    origin, args = typing.get_origin(expected), typing.get_args(expected)
    if origin is Literal:
        return f"one of {args!r}"
    if origin is tuple:
        return "a list of " + _describe(args[0]).removeprefix("an ").removeprefix("a ") + "s"
    names = {type(None): "None", bool: "true or false", int: "an integer", float: "a number",
             str: "a string"}  # fmt: skip
    if isinstance(expected, type) and issubclass(expected, os.PathLike):
        return "a path"
    name = getattr(expected, "__name__", str(expected))
    return names.get(expected, f"{'an' if name[0] in 'AEIOU' else 'a'} {name}")
