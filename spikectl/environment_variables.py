"""The environment variables spikectl's libraries read when they load, checked before they do.

Numba reads its settings from the environment once, when it is imported (and the
threading layer when a kernel first runs on threads). A value it cannot use is a
traceback from inside Numba (``NUMBA_NUM_THREADS=0``: a ValueError at import), a
multi-line warning that prints one (``NUMBA_NUM_THREADS=four``), or a crash (a thread
count far beyond the machine's: a segmentation fault when the threads start).
:func:`check_environment` refuses such a value first, with one
:class:`EnvironmentVariableError` naming the variable: ``import spikectl`` raises it
(the Python API), and the ``spikectl`` command prints it as one line and exits 2.

``spikectl/__init__`` calls :func:`check_environment` and :func:`import_numba` before it
imports anything else; this module imports only the standard library.
"""

from __future__ import annotations

import os
import re
import sys
import warnings
from collections.abc import Mapping

__all__ = [
    "EnvironmentVariableError",
    "MAX_NUMBA_THREADS",
    "check_environment",
    "import_numba",
    "threading_layer_error",
]

MAX_NUMBA_THREADS = 4096
"""The most threads ``NUMBA_NUM_THREADS`` may ask for. Numba starts them all when a
kernel first runs on threads; 100 000 crashed the process (a segmentation fault)."""

NUMBA_THREADING_LAYERS = ("default", "safe", "threadsafe", "forksafe", "tbb", "omp", "workqueue")
"""The values ``NUMBA_THREADING_LAYER`` may take (Numba's documentation, any case)."""

NUMBA_FLAGS = ("NUMBA_DISABLE_JIT",)
"""Numba's switches that spikectl's documentation names (docs/model.md): whole numbers."""

_NUMBA_WARNING = re.compile(
    r"Environment variable '(?P<name>[^']*)' is defined but its associated value "
    r"'(?P<value>.*?)' could not be parsed",
    re.DOTALL,
)
_numba_refused: list[EnvironmentVariableError] = []


class EnvironmentVariableError(ValueError):
    """An environment variable that a library spikectl loads cannot use; ``name`` and
    ``value`` are the variable and what it holds."""

    def __init__(self, name: str, value: str, problem: str) -> None:
        self.name = name
        self.value = value
        super().__init__(f"the environment variable {name}={value!r}: {problem}")


def check_environment(environ: Mapping[str, str] | None = None) -> None:
    """Refuse, with an :class:`EnvironmentVariableError`, an environment variable that
    Numba would fail on, crash on or ignore with a traceback-bearing warning.

    ``environ`` defaults to ``os.environ``. An unset variable is always fine.
    """
    environ = os.environ if environ is None else environ
    value = environ.get("NUMBA_NUM_THREADS")
    if value is not None:
        threads = _integer(value)
        if threads is None or not 1 <= threads <= MAX_NUMBA_THREADS:
            raise EnvironmentVariableError(
                "NUMBA_NUM_THREADS",
                value,
                f"Numba's thread count must be a whole number from 1 to {MAX_NUMBA_THREADS} "
                "(unset it for one thread per CPU)",
            )
    value = environ.get("NUMBA_THREADING_LAYER")
    if value is not None and value.strip().lower() not in NUMBA_THREADING_LAYERS:
        raise EnvironmentVariableError(
            "NUMBA_THREADING_LAYER",
            value,
            f"Numba's threading layer must be one of {', '.join(NUMBA_THREADING_LAYERS)}",
        )
    value = environ.get("NUMBA_THREADING_LAYER_PRIORITY")
    if value is not None and sorted(value.split()) != ["omp", "tbb", "workqueue"]:
        raise EnvironmentVariableError(
            "NUMBA_THREADING_LAYER_PRIORITY",
            value,
            "it must name tbb, omp and workqueue, each once, separated by spaces",
        )
    for name in NUMBA_FLAGS:
        value = environ.get(name)
        if value is not None and _integer(value) is None:
            raise EnvironmentVariableError(name, value, "it must be a whole number (1: on)")


def import_numba() -> None:
    """Import Numba, refusing (with an :class:`EnvironmentVariableError`) any ``NUMBA_*``
    variable it cannot parse: Numba would warn, with its own traceback in the warning,
    and go on without the setting. Numba's other warnings pass through."""
    if _numba_refused:  # Numba stays imported: a second try fails as the first did
        raise _numba_refused[0]
    if "numba" in sys.modules:
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import numba  # noqa: F401
    for warning in caught:
        match = _NUMBA_WARNING.match(str(warning.message))
        if match:
            error = EnvironmentVariableError(
                match["name"], match["value"], "Numba cannot read it (unset it or correct it)"
            )
            _numba_refused.append(error)
            raise error
    for warning in caught:
        warnings.warn_explicit(warning.message, warning.category, warning.filename,
                               warning.lineno)  # fmt: skip


def _integer(text: str) -> int | None:
    """``text`` as Numba reads an integer (``int(text)``), or None."""
    try:
        return int(text)
    except ValueError:
        return None


def threading_layer_error(error: ValueError) -> EnvironmentVariableError:
    """The error to raise for Numba's refusal to start its threads (``error``): the
    threading layer asked for is not installed (``NUMBA_THREADING_LAYER=tbb`` without
    TBB) or none can be loaded."""
    value = os.environ.get("NUMBA_THREADING_LAYER", "default")
    problem = " ".join(str(error).split())
    return EnvironmentVariableError(
        "NUMBA_THREADING_LAYER",
        value,
        f"Numba cannot start its threads with it ({problem}); unset it or choose "
        "one that is installed (workqueue always is)",
    )
