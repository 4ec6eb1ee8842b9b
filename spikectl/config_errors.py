"""Config errors as data: a validation error that carries the path of the field it is about.

Every config of spikectl (the training tree, NeuronParams, Extensions, the network sizes)
refuses a bad value with a :class:`ConfigError`. Its message reads as before
(``"gamma must lie in [0, 1], got 2"``: the field's name, then what is wrong), and its
``path`` names the field within the whole tree (``("learner", "gamma")``), so that the
command line can name the flag by a lookup (``spikectl.cli``), never by reading the text.
"""

from __future__ import annotations

from typing import Any


class ConfigError(ValueError):
    """A config field with a bad value; ``path`` is the field's place in the tree."""

    def __init__(self, field: str | tuple[str, ...], problem: str) -> None:
        self.path: tuple[str, ...] = (field,) if isinstance(field, str) else tuple(field)
        self.problem = problem
        super().__init__(f"{self.path[-1]} {problem}")

    def within(self, *prefix: str) -> ConfigError:
        """The same error, its path lengthened by the enclosing fields ``prefix``."""
        return ConfigError((*prefix, *self.path), self.problem).with_traceback(None)

    @property
    def dotted(self) -> str:
        """The field's dotted path, e.g. ``learner.gamma``."""
        return ".".join(self.path)


def check_int(name: str, value: Any, low: int, high: int | None = None, what: str = "") -> None:
    """Refuse ``value`` for field ``name`` unless it is an int (not a bool) in [low, high]."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < low
        or (high is not None and value > high)
    ):
        raise ConfigError(name, f"must be {what}, got {value!r}")
