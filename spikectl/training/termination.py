"""SIGTERM while a run trains: finish the round, write a checkpoint, stop.

SIGTERM is what Slurm (at a job's time limit, or ``scancel``) and Docker (``docker
stop``) send before they kill a process, after a grace period (Slurm's ``KillWait``, 30 s
by default; Docker's 10 s). Python's default lets it kill the process at once, without a
word and without a checkpoint, so a job lost everything since its last scheduled one.
While the training loop runs, :func:`deferred_termination` takes SIGTERM instead: the
round under way finishes, the loop writes a checkpoint of that point and raises
:class:`TrainingTerminated`, and ``spikectl train --resume`` continues exactly from it. A
second SIGTERM while the round finishes ends the run at once (from its last checkpoint),
as a second Ctrl-C would.

Both errors are KeyboardInterrupts, so every caller that ends on a Ctrl-C (a sweep, the
command line: one line and exit 143 = 128 + 15 instead of 130) ends on them the same way,
and none of the ``except Exception`` clean-ups of a refused start takes them for a refusal.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path


class Terminated(KeyboardInterrupt):
    """The process was asked to end by SIGTERM (the message, if any, says what was kept)."""

    signum = signal.SIGTERM


class TrainingTerminated(Terminated):
    """A run stopped by SIGTERM after writing a checkpoint of the round it finished."""

    def __init__(self, where: Path, episodes: int) -> None:
        resume = f"spikectl train --resume {where}"
        if where.parent.name == "trials":  # a sweep's trial
            resume += ", or the same sweep command"
        super().__init__(
            f"terminated (SIGTERM): checkpoint written at episode {episodes:,} in {where}; "
            f"continue with {resume}"
        )
        self.where, self.episodes = where, episodes


@contextlib.contextmanager
def deferred_termination() -> Iterator[Callable[[], bool]]:
    """Within the block, a first SIGTERM is only recorded: the block asks
    ``requested()`` at its safe points. A second SIGTERM goes to the handler that was
    there before (the command line's, which raises :class:`Terminated`), or raises
    :class:`Terminated` where that was the default. Only in the main thread (the one
    Python runs signal handlers in), and never where SIGTERM was ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous is signal.SIG_IGN or previous is None:
        yield lambda: False
        return
    received: list[int] = []

    def on_terminate(signum, frame):
        if not received:
            received.append(signum)
            return None
        if callable(previous):
            return previous(signum, frame)
        raise Terminated

    signal.signal(signal.SIGTERM, on_terminate)
    try:
        yield lambda: bool(received)
    finally:
        signal.signal(signal.SIGTERM, previous)
