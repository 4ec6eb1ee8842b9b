"""How a Ctrl-C (or SIGTERM) ends a ``spikectl`` command: one line, exit 130 (143),
whatever it interrupted.

Python loses or garbles a Ctrl-C in four places, and each has its owner here:

- **Inside llvmlite**, the binding through which Numba's compiler drives LLVM the first
  time a kernel is used: a KeyboardInterrupt there could be lost in LLVM's callback into
  Python (its object cache: "Exception ignored on calling ctypes callback function", and
  the command went on), leave the compiler half-built (a RuntimeError "no compiled object
  yet" instead of the interrupt), or crash the process as it exits.
  ``interrupts_delivered`` holds the Ctrl-C until llvmlite's call has returned, then
  raises it.
- **Inside any other C library's callback into Python** (a weak reference's): Python can
  only print the KeyboardInterrupt as "Exception ignored ..." and carry on, so the command
  ran to its end. ``interrupts_delivered`` takes that report and raises the interrupt again
  once the callback has returned.
- **Inside a Numba kernel** the KeyboardInterrupt comes back as a ``SystemError`` caused
  by it (``caused_by_interrupt`` follows the chain).
- **While the process shuts down** (about a second with PyTorch and Numba loaded) a second
  press would end it by the signal instead of 130, or interrupt a module half-way through
  its teardown; ``ignore_interrupts_at_exit`` lets it pass.

SIGTERM (what Slurm and Docker send before they kill) ends a command the same way, with
its own line and exit 143 (128 + 15): ``interrupts_delivered`` raises
:class:`~spikectl.training.termination.Terminated`, a KeyboardInterrupt, held back inside
llvmlite as a Ctrl-C is. A training run takes SIGTERM itself while it trains: it finishes
the round, writes a checkpoint and then stops (``spikectl.training.termination``).

The installed ``spikectl`` script's launcher (``_spikectl_launcher``) covers the imports
before this package has loaded, with the standard library only.
"""

from __future__ import annotations

import _thread
import atexit
import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

from spikectl.training.termination import Terminated

INTERRUPTED = (
    "spikectl: interrupted (a training run or sweep continues from its last checkpoint: "
    "spikectl train --resume RUN_DIR, or the same sweep command)"
)
TERMINATED = (
    "spikectl: terminated (SIGTERM) (a training run or sweep continues from its last "
    "checkpoint: spikectl train --resume RUN_DIR, or the same sweep command)"
)
TERMINATED_EXIT_STATUS = 128 + signal.SIGTERM
"""143, as a shell reports a process SIGTERM ended (Slurm and Docker read it so)."""
REDELIVERY_DELAY_S = 0.05
"""Seconds between a Ctrl-C held back (or lost in a callback) and raising it again: time
for a callback to return to its C caller (microseconds); inside llvmlite it is checked
again at this interval until llvmlite's call has returned."""
NOT_INTERRUPTED = ("llvmlite",)
"""Top-level packages whose Python code a Ctrl-C waits for: llvmlite, the binding between
Numba's compiler and LLVM (each of its calls returns within a second or so; Numba's own
passes, which can run for many seconds, may be interrupted)."""


class _Redelivery:
    """At most one timer that simulates ``signum`` (SIGINT, or SIGTERM) again
    (``_thread.interrupt_main``)."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        self.signum = signum
        self.timer: threading.Timer | None = None  # the redelivery not yet fired
        self.lost_in_a_callback = False

    def arm(self) -> None:
        if self.timer is None:
            self.timer = threading.Timer(REDELIVERY_DELAY_S, self._fire)
            self.timer.daemon = True
            self.timer.start()

    def _fire(self) -> None:
        self.timer = None  # first, so that a second hold or loss re-arms
        _thread.interrupt_main(self.signum)

    def cancel(self) -> bool:
        """Cancel a redelivery not yet fired; whether there was one."""
        timer, self.timer = self.timer, None
        if timer is not None:
            timer.cancel()
        return timer is not None


@contextlib.contextmanager
def interrupts_delivered() -> Iterator[None]:
    """Within this block a Ctrl-C is never lost, and never lands inside llvmlite.

    SIGINT's handler (Python's, or the launcher's) is wrapped: while the main thread runs
    code of a ``NOT_INTERRUPTED`` package, the Ctrl-C is held and checked again every
    ``REDELIVERY_DELAY_S``; elsewhere the wrapped handler raises as before.
    ``sys.unraisablehook`` receives a KeyboardInterrupt that a callback could not
    propagate; instead of printing it, the interrupt is raised again shortly after, and an
    error the lost interrupt left behind is reported as the interrupt. A Ctrl-C still held
    when the block finishes is raised at its end: the user pressed it. Any other
    unraisable exception goes to the hook that was there before.
    """
    redelivery, termination = _Redelivery(), _Redelivery(signal.SIGTERM)
    previous_hook = sys.unraisablehook
    previous_handler = signal.getsignal(signal.SIGINT)
    main_thread = threading.current_thread() is threading.main_thread()
    # Only where a Python handler would raise (a job started in the background ignores
    # SIGINT), and only in the main thread, the one Python's signal handlers run in.
    wrapped = previous_handler if callable(previous_handler) and main_thread else None
    # SIGTERM only where it would kill the process (never where it is ignored or handled).
    terminates = main_thread and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL

    def unraisable(report: sys.UnraisableHookArgs) -> None:
        if not isinstance(report.exc_value, KeyboardInterrupt):
            previous_hook(report)
            return
        lost = termination if isinstance(report.exc_value, Terminated) else redelivery
        lost.lost_in_a_callback = True
        lost.arm()

    sys.unraisablehook = unraisable
    if wrapped is not None:
        signal.signal(signal.SIGINT, _held_inside(wrapped, redelivery))
    if terminates:
        signal.signal(signal.SIGTERM, _held_inside(_terminate, termination))
    try:
        yield
    except BaseException as error:  # noqa: B036 - only re-labelled, always re-raised
        if termination.lost_in_a_callback and not caused_by_interrupt(error):
            raise Terminated from error
        if redelivery.lost_in_a_callback and not caused_by_interrupt(error):
            raise KeyboardInterrupt from error
        raise
    finally:
        sys.unraisablehook = previous_hook
        if wrapped is not None:
            signal.signal(signal.SIGINT, wrapped)
        if terminates:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
        held, held_termination = redelivery.cancel(), termination.cancel()
    if held_termination:  # only reached when the block itself raised nothing
        raise Terminated
    if held:
        raise KeyboardInterrupt


def _terminate(signum: int, frame: FrameType | None) -> None:
    """SIGTERM's handler: end the command as a Ctrl-C would, with its own line and exit
    status (a training run takes SIGTERM itself: it checkpoints first)."""
    raise Terminated


def terminated_by(error: BaseException | None) -> Terminated | None:
    """The :class:`Terminated` that ``error`` is or was caused by (SIGTERM), or None."""
    found = _in_chain(error, Terminated)
    return found if isinstance(found, Terminated) else None


def _held_inside(
    handler: Callable[[int, FrameType | None], Any], redelivery: _Redelivery
) -> Callable[[int, FrameType | None], Any]:
    """SIGINT's ``handler``, except while the main thread runs a ``NOT_INTERRUPTED``
    package's code: then the Ctrl-C waits for ``redelivery``."""

    def on_interrupt(signum: int, frame: FrameType | None) -> Any:
        if _inside(frame, NOT_INTERRUPTED):
            redelivery.arm()
            return None
        return handler(signum, frame)  # raises KeyboardInterrupt

    return on_interrupt


def _inside(frame: FrameType | None, packages: tuple[str, ...]) -> bool:
    """Whether ``frame`` or any frame that called it runs code of one of ``packages``."""
    while frame is not None:
        if frame.f_globals.get("__name__", "").partition(".")[0] in packages:
            return True
        frame = frame.f_back
    return False


def caused_by_interrupt(error: BaseException | None) -> bool:
    """Whether ``error`` is, or was caused by, a KeyboardInterrupt (Numba returns one
    raised inside a kernel as a SystemError caused by it)."""
    return _in_chain(error, KeyboardInterrupt) is not None


def _in_chain(error: BaseException | None, kind: type[BaseException]) -> BaseException | None:
    """The first exception of ``kind`` in ``error``'s chain of causes (``__cause__``, else
    ``__context__``; a cycle ends the walk), or None."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, kind):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None


def ignore_interrupts_at_exit() -> None:
    """Let a further Ctrl-C or SIGTERM pass while the process shuts down (an exit handler).

    Only at exit: a caller that catches the SystemExit (a notebook, a docs build) keeps
    its Ctrl-C. The ``spikectl`` command's launcher does the same around ``main``.
    """
    atexit.unregister(_ignore_interrupts)  # once, however often main was interrupted
    atexit.register(_ignore_interrupts)


def _ignore_interrupts() -> None:
    with contextlib.suppress(ValueError):  # not the main thread
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one, after the first
