"""Output of the commands that write result files: the files are written whatever
happens to standard output.

A reader that goes away early (``spikectl benchmark ... --out o.csv | head -1``) closes
the pipe; printing then raises BrokenPipeError. :class:`Printer` swallows it, sends the
rest of the printing to ``/dev/null``, lets the command finish and write its files, and
:meth:`Printer.finish` then raises BrokenPipeError so that ``spikectl`` exits quietly
(status 141) as a shell tool does. Output paths are checked before any work by
:func:`check_outputs`, and claimed for the whole command by :func:`claimed_outputs`: an
existing file is never replaced without ``--overwrite`` and a second command writing the
same file at the same time is refused.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from spikectl.files import check_distinct_outputs, check_output_path
from spikectl.locks import output_lock


class Printer:
    """``print`` that survives a closed standard output until :meth:`finish`."""

    def __init__(self) -> None:
        self.closed = False

    def __call__(self, text: str = "") -> None:
        if self.closed:
            return
        try:
            print(text, flush=True)
        except BrokenPipeError:
            self.closed = True
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)

    def finish(self) -> None:
        """Raise BrokenPipeError (after the files are written) if the reader went away."""
        if self.closed:
            raise BrokenPipeError


def check_outputs(outputs: Iterable[tuple[str, Path | None]]) -> None:
    """Refuse, before any work, output flags that would damage something: a folder, an
    existing FIFO, device or link, a run directory's own file, or two flags naming one
    file (``files.check_output_path``, ``files.check_distinct_outputs``)."""
    from spikectl.training.run_files import RUN_FILE_NAMES

    outputs = list(outputs)
    for flag, path in outputs:
        if path is not None:
            check_output_path(path, flag, RUN_FILE_NAMES)
    check_distinct_outputs(outputs)


@contextmanager
def claimed_outputs(outputs: Iterable[tuple[str, Path | None]], overwrite: bool) -> Iterator[None]:
    """For the block, hold the output files of a command, checked before any work
    (:func:`check_outputs`): each file's lock (``locks.output_lock``: a second writer of
    the same file meanwhile is refused, naming this process), and, without
    ``overwrite``, a refusal of any that exists, as ``spikectl contexts`` refuses
    existing sets. Write them with ``replace=overwrite`` so that a file made meanwhile
    by anything else is not replaced either."""
    outputs = list(outputs)
    check_outputs(outputs)
    with ExitStack() as locks:
        for flag, path in outputs:
            if path is None:
                continue
            locks.enter_context(output_lock(path, flag))
            if not overwrite and os.path.lexists(path):  # under the lock: no writer is midway
                raise ValueError(
                    f"{flag}: {path} exists: pass --overwrite to replace it, or choose "
                    f"another {flag}"
                )
        yield


def refuse_existing(out_dir: Path, names: tuple[str, ...], overwrite: bool) -> None:
    """Refuse, unless ``overwrite``, to write ``names`` in the folder ``out_dir`` where
    any exists (called under the folder's lock, ``locks.folder_lock``, so that no other
    spikectl command is midway)."""
    existing = [str(out_dir / name) for name in names if os.path.lexists(out_dir / name)]
    if existing and not overwrite:
        raise ValueError(
            f"--out-dir: {' and '.join(existing)} exist(s): pass --overwrite to replace, "
            "or choose another --out-dir"
        )
