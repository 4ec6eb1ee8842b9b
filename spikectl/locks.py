"""Locks that keep two writers from sharing one output: a folder (a run directory, a
sweep) is held with :func:`folder_lock`, a command's output file with :func:`output_lock`,
for as long as the command writes them; a second writer is refused in one line naming the
holder's pid. Both are ``fcntl.flock`` locks, which the kernel releases when their process
ends however it ends (Ctrl-C, SIGKILL, a crash), so a lock file left behind holds nothing.

Like :mod:`spikectl.files`, at the bottom of the layering.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from spikectl.files import FileWriteError, describe_os_error, make_dirs


class FolderBusyError(ValueError):
    """Another process holds a folder's lock (two writers would lose one's results)."""


LOCK_FILE = ".spikectl.lock"
"""The lock file :func:`folder_lock` holds in a folder (a run directory's too)."""


@contextmanager
def folder_lock(
    folder: Path, doing: str, busy: type[Exception] = FolderBusyError
) -> Iterator[None]:
    """Hold ``folder/.spikectl.lock`` (made with the folder) for the block; while another
    process holds it, a ``busy`` error naming that process and ``doing`` (what the holder
    is doing in the folder). The lock dies with its process, even on SIGKILL. A folder
    this call made and that holds nothing else at the end is removed again."""
    import contextlib
    import fcntl

    created = not folder.exists()
    make_dirs(folder)
    path = folder / LOCK_FILE
    try:
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as error:
        raise FileWriteError(
            error.errno, f"cannot write {path}: {describe_os_error(error)}"
        ) from error
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = os.pread(descriptor, 32, 0).decode(errors="replace").strip() or "unknown"
            raise busy(
                f"another process (pid {owner}) is {doing} in {folder}: wait for it to "
                "finish or stop it; two writers must never share one folder"
            ) from None
        os.ftruncate(descriptor, 0)
        os.pwrite(descriptor, f"{os.getpid()}\n".encode(), 0)
        try:
            yield
        finally:
            if created and {p.name for p in folder.iterdir()} == {LOCK_FILE}:
                # Nothing was made: leave no empty folder behind.
                path.unlink(missing_ok=True)
                with contextlib.suppress(OSError):
                    folder.rmdir()
    finally:
        os.close(descriptor)


class OutputBusyError(FolderBusyError):
    """Another process is writing the same output file (one's results would be lost)."""


def lock_path_of(path: str | os.PathLike) -> Path:
    """The lock file :func:`output_lock` holds for the output ``path``: ``.NAME.lock``
    beside the file the path resolves to, so every spelling of one file shares it."""
    real = Path(os.path.realpath(path))
    return real.parent / f".{real.name}.lock"


@contextmanager
def output_lock(path: str | os.PathLike, flag: str) -> Iterator[None]:
    """Hold the lock of the output file ``path`` for the block: while another process
    holds it, an :class:`OutputBusyError` naming ``flag``, the file and that process.

    The lock is ``fcntl.flock`` on :func:`lock_path_of`, which the kernel releases when its
    process ends however it ends (Ctrl-C, SIGKILL, a crash): a lock file left behind by a
    dead process holds nothing and is taken over. The file is removed on release; folders
    made for it are removed again if nothing else was written in them.
    """
    import fcntl

    lock = lock_path_of(path)
    made = _missing_folders(lock.parent)
    make_dirs(lock.parent)
    try:
        descriptor = _take_lock(lock, flag, path)
        try:
            yield
        finally:
            lock.unlink(missing_ok=True)  # before unlocking: a waiter sees a new file
            fcntl.flock(descriptor, fcntl.LOCK_UN)
            os.close(descriptor)
    finally:
        for folder in made:  # deepest first; only empty ones go
            try:
                folder.rmdir()
            except OSError:
                break


def _missing_folders(folder: Path) -> list[Path]:
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def _take_lock(lock: Path, flag: str, path: str | os.PathLike) -> int:
    """An open descriptor of ``lock`` holding its exclusive flock, or OutputBusyError."""
    import fcntl

    while True:
        try:
            descriptor = os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
        except OSError as error:
            raise FileWriteError(
                error.errno, f"cannot write {lock}: {describe_os_error(error)}"
            ) from error
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = os.pread(descriptor, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(descriptor)
            raise OutputBusyError(
                f"{flag} {path}: another process (pid {owner}) is writing that file: wait for "
                "it to finish or stop it, or choose another name; two writers of one file "
                "would lose one's results"
            ) from None
        # The previous holder removes the file as it lets go: a lock taken on the removed
        # file guards nothing, so open the new one and lock again.
        try:
            current = os.stat(lock)
            held = os.fstat(descriptor)
            if (current.st_dev, current.st_ino) == (held.st_dev, held.st_ino):
                os.ftruncate(descriptor, 0)
                os.pwrite(descriptor, f"{os.getpid()}\n".encode(), 0)
                return descriptor
        except FileNotFoundError:
            pass
        os.close(descriptor)
