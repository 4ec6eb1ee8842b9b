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
        error = ConfigError((*prefix, *self.path), self.problem, label=self.label, sep=self.sep)
        return error.with_traceback(None)

    def naming(self, name: str) -> str:
        """The message with ``name`` (a flag, say) for the field:
        ``naming("--gamma")`` is ``"--gamma must lie in [0, 1], got 2"``."""
        return f"{name}{self.sep if self.label else ': '}{self.problem}"

    def __reduce__(self) -> tuple[Any, ...]:
        # Pickled whole (e.g. from a sweep's worker process), not from the message alone.
        return _config_error, (self.path, self.problem, self.label, self.sep)

    @property
    def dotted(self) -> str:
        """The field's dotted path, e.g. ``learner.gamma``."""
        return ".".join(self.path)


class MissingExtraError(ImportError):
    """An optional dependency a feature needs is not installed; the message names the
    pip extra that installs it (``pip install "spikectl[ray]"``)."""


def _config_error(path: tuple[str, ...], problem: str, label: str, sep: str) -> ConfigError:
    return ConfigError(path, problem, label=label, sep=sep)


def check_int(name: str, value: Any, low: int, high: int | None = None, what: str = "") -> None:
    """Refuse ``value`` for field ``name`` unless it is an int (not a bool) in [low, high]."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < low
        or (high is not None and value > high)
    ):
        raise ConfigError(name, f"must be {what}, got {value!r}")
