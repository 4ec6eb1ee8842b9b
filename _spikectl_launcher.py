"""The ``spikectl`` command's entry point (``[project.scripts]`` in pyproject.toml).

It stands outside the ``spikectl`` package on purpose: importing any module inside the
package first runs ``spikectl/__init__``, which checks the environment and loads Numba,
and the command then loads PyTorch and its options (a second or more). A Ctrl-C in that
time, or an environment variable Numba cannot use (``NUMBA_NUM_THREADS=0``), would
otherwise be a Python traceback from inside an import. Here both are caught around the
import of the command: a Ctrl-C is one line and exit 130, a bad environment variable one
line and exit 2 (``spikectl.environment_variables``). This module imports only the standard
library, and nothing imports it: it is a process's entry, not a library.

A Ctrl-C is recognised by the signal, not only by the error it leaves: an extension
module interrupted while it initialises may replace the KeyboardInterrupt with an error
of its own and no chain back to it (numpy on Python 3.10: ``PyCapsule_Import could not
import module "datetime"``). So the launcher's SIGINT handler records the signal, then
raises KeyboardInterrupt as Python's own handler does. Raised inside a callback (a weak
reference's, during an import), Python can only print the KeyboardInterrupt as "Exception
ignored" and go on: the launcher keeps that print out and, once the import returns, still
ends with its one line and 130 (during the command, ``spikectl.cli.interrupts`` raises it
again as soon as the callback has returned).

What it cannot cover is Python's own start, before this module runs (a few tens of
milliseconds: the interpreter and its ``site`` imports); a Ctrl-C then is Python's.
"""

from __future__ import annotations

import os
import signal
import sys

INTERRUPTED_STARTING = "spikectl: interrupted while starting (nothing was run)"
INTERRUPTED = "spikectl: interrupted"

_signals_received: list[int] = []  # the SIGINTs this process has had (see _record_interrupt)


def main() -> None:
    """Run the ``spikectl`` command on ``sys.argv``; see the module's docstring."""
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        # Only where Ctrl-C would interrupt anyway: a job started in the background
        # ignores SIGINT, and keeps ignoring it.
        signal.signal(signal.SIGINT, _record_interrupt)
        sys.unraisablehook = _quiet_about_interrupts(sys.unraisablehook)
    try:
        from spikectl.cli import main as command  # the package, Numba, tyro, the commands
    except BaseException as error:  # noqa: B036 - a Ctrl-C is the point
        _ignore_interrupts()
        if _interrupted(error):
            _exit_now(INTERRUPTED_STARTING, 130)
        environment_error = sys.modules.get("spikectl.environment_variables")
        if environment_error is not None and isinstance(
            error, environment_error.EnvironmentVariableError
        ):
            _exit_now(f"spikectl: error: {error}", 2)
        raise
    if _signals_received:  # a Ctrl-C Python could only report (it came in a callback)
        _ignore_interrupts()
        _exit_now(INTERRUPTED_STARTING, 130)
    try:
        command()  # its own Ctrl-C handling: one line and 130 (spikectl.cli.main)
    except SystemExit:
        raise
    except BaseException as error:  # noqa: B036 - a Ctrl-C outside the command's handling
        _ignore_interrupts()
        if not _interrupted(error):
            raise
        print(INTERRUPTED, file=sys.stderr)
        raise SystemExit(130) from None
    else:
        if _signals_received:  # as above: the command went on, but the user stopped it
            _ignore_interrupts()
            print(INTERRUPTED, file=sys.stderr)
            raise SystemExit(130)
    finally:
        # The command has finished or is exiting: a Ctrl-C from here on, while Python
        # shuts down, would only be a traceback from its exit handlers.
        _ignore_interrupts()


def _record_interrupt(signum: int, frame: object) -> None:
    """Python's default SIGINT handler, which also remembers that the signal came."""
    _signals_received.append(signum)
    raise KeyboardInterrupt


def _quiet_about_interrupts(hook):
    """``sys.unraisablehook`` that leaves out a recorded Ctrl-C: raised inside a callback
    (a weak reference's, a ``__del__``), Python can only print it as "Exception ignored"
    and go on; the launcher reports it as its one line instead."""

    def unraisable(report) -> None:
        if isinstance(report.exc_value, KeyboardInterrupt) and _signals_received:
            return
        hook(report)

    return unraisable


def _ignore_interrupts() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _exit_now(line: str, code: int) -> None:
    """Print ``line`` on stderr and end the process with ``code``, skipping the exit
    handlers of the half-imported libraries (nothing has run that could need them)."""
    print(line, file=sys.stderr)
    sys.stderr.flush()
    sys.stdout.flush()
    os._exit(code)


def _interrupted(error: BaseException | None) -> bool:
    """Whether a Ctrl-C came, or ``error`` is or was caused by a KeyboardInterrupt (an
    extension module interrupted while it initialises may report it as the cause of
    another error, or replace it: see the module's docstring). The chain test is
    ``spikectl.cli.interrupts.caused_by_interrupt``, which this module cannot import."""
    if _signals_received:
        return True
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False


if __name__ == "__main__":
    main()
