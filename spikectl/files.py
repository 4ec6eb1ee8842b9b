"""Writing files so that nothing is ever half-written, and reading them within bounds.

Every file spikectl writes (context sets, run directories, sweep files, figures) goes
through :func:`atomic_write`: the data go to a temporary file in the same folder, are
flushed to disk, and the temporary file is renamed over the target. A crash, a
``SIGKILL`` or a full disk at any moment leaves either the previous file or the new
one, never half of one. Failures of the file system (no space, read-only, no
permission, a file where a folder should be) become one :class:`FileWriteError`
naming the file and the problem. ``replace=False`` never replaces an existing file.

Every file spikectl reads that a user could have replaced (run files, sweep files,
context sets, checkpoints) is opened through :func:`open_regular_file`: a FIFO would
block the reader forever and a link to ``/dev/zero`` would feed it until memory runs
out, so anything that is not a regular file is refused with a
:class:`NotARegularFileError`, and :func:`read_text_file` bounds what it reads.

This module is at the bottom of the layering: it imports nothing from spikectl.
"""

from __future__ import annotations

import errno
import functools
import json
import os
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

_PROBLEMS = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.EISDIR: "the path is a folder, not a file",
    errno.ENAMETOOLONG: "the file name is too long",
}


class FileWriteError(OSError):
    """A file could not be written (full disk, read-only, no permission, ...).

    The message names the file and the problem; any previous version of the file is
    intact. ``errno`` is that of the underlying error.
    """

    def __str__(self) -> str:
        return str(self.strerror)


class TooLargeError(ValueError):
    """A size that would need more memory than this machine has (names the setting)."""


class NotARegularFileError(OSError):
    """A path to read names something that is not a regular file (a FIFO, a device, a
    socket): reading it could block forever or never end. An OSError, so every reader's
    ``except OSError`` reports it as the file's problem."""

    def __str__(self) -> str:
        return f"{self.filename}: {self.strerror}"


MAX_TEXT_FILE_BYTES = 64 * 2**20
"""The most :func:`read_text_file` reads by default: far above any config, sweep file or
metrics.csv spikectl writes, far below what would hurt."""


def _file_kind(mode: int) -> str:
    for test, kind in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISDIR, "a folder")):  # fmt: skip
        if test(mode):
            return kind
    return "something else"


@contextmanager
def open_regular_file(path: str | os.PathLike) -> Iterator[IO[bytes]]:
    """Open ``path`` for reading in binary mode, refusing anything but a regular file.

    The file is opened without blocking and checked on the open descriptor (``fstat``),
    so a FIFO swapped in after a check cannot block the reader. Raises
    FileNotFoundError, NotARegularFileError or another OSError.
    """
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    descriptor = os.open(path, flags)
    try:
        mode = os.fstat(descriptor).st_mode
        if not stat.S_ISREG(mode):
            raise NotARegularFileError(
                None, f"it is {_file_kind(mode)}, not a regular file", os.fspath(path)
            )
        os.set_blocking(descriptor, True)
        handle = os.fdopen(descriptor, "rb")
    except BaseException:
        os.close(descriptor)
        raise
    with handle:
        yield handle


def check_output_path(
    path: str | os.PathLike, flag: str, protected: Iterable[str] = ()
) -> None:
    """Refuse an output path a write would damage, before any work is done: a folder,
    an existing FIFO, device, socket or symbolic link (the writer would replace it with
    a file), or a file whose name is in ``protected`` in a folder that holds a spikectl
    run (``config.json`` beside it): a run's own files are never an output. ValueError
    naming ``flag``."""
    path = Path(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as error:
        raise ValueError(f"{flag} {path}: {describe_os_error(error)}") from None
    if mode is not None and stat.S_ISLNK(mode):
        raise ValueError(
            f"{flag} {path}: it is a symbolic link; give the file it points to, or a new name"
        )
    if mode is not None and not stat.S_ISREG(mode):
        raise ValueError(f"{flag} {path}: it is {_file_kind(mode)}, not a regular file")
    if path.name in set(protected) and (path.parent / "config.json").is_file():
        raise ValueError(
            f"{flag} {path}: that is a file of the run in {path.parent}; writing there "
            "would destroy it: give another name"
        )


def check_distinct_outputs(outputs: Iterable[tuple[str, str | os.PathLike | None]]) -> None:
    """Refuse two output flags naming the same file (one would clobber the other)."""
    seen: dict[str, str] = {}
    for flag, path in outputs:
        if path is None:
            continue
        key = os.path.realpath(path)
        if key in seen:
            raise ValueError(f"{seen[key]} and {flag} name the same file {path}: give two files")
        seen[key] = flag


def check_regular_file(path: str | os.PathLike) -> None:
    """Refuse a path (after links) that is not a regular file, before a library that
    takes a path (NumPy, PyTorch, zipfile) opens it: NotARegularFileError."""
    mode = os.stat(path).st_mode
    if not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
        raise NotARegularFileError(
            None, f"it is {_file_kind(mode)}, not a regular file", os.fspath(path)
        )


def read_text_file(path: str | os.PathLike, max_bytes: int = MAX_TEXT_FILE_BYTES) -> str:
    """The UTF-8 text of the regular file ``path``, at most ``max_bytes`` long (a longer
    file is a TooLargeError naming it); decoding errors raise UnicodeDecodeError."""
    with open_regular_file(path) as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise TooLargeError(
            f"{os.fspath(path)} is larger than {max_bytes:,} bytes: not a file spikectl wrote"
        )
    return data.decode("utf-8")


def read_json_file(path: str | os.PathLike, max_bytes: int = MAX_TEXT_FILE_BYTES) -> Any:
    """The JSON value in the regular file ``path`` (:func:`read_text_file`); JSON nested
    too deeply to parse is a ValueError (json.JSONDecodeError is one too), not a
    RecursionError."""
    text = read_text_file(path, max_bytes)
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("its JSON is nested too deeply to read") from None


def describe_os_error(error: OSError) -> str:
    """A short description of a file-system error, without the Python exception clutter."""
    return _PROBLEMS.get(error.errno, error.strerror or str(error))


def make_dirs(path: Path) -> None:
    """``mkdir -p`` that fails with a :class:`FileWriteError` naming the folder."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise FileWriteError(
            errno.ENOTDIR, f"cannot create the folder {path}: a file of that name exists"
        ) from None
    except OSError as error:
        raise FileWriteError(
            error.errno, f"cannot create the folder {path}: {describe_os_error(error)}"
        ) from error


def atomic_write(
    path: str | os.PathLike, write: Callable[[IO[bytes]], None], replace: bool = True
) -> Path:
    """Write a file atomically: ``write(handle)`` fills a temporary file, which is then
    renamed over ``path``. Returns ``path``.

    On any failure the temporary file is removed and the previous ``path`` (if any) is
    left untouched; file-system failures raise :class:`FileWriteError`. ``replace=False``:
    an existing ``path`` is never replaced, even one made while ``write`` ran (the new
    file is linked into place, which fails if the name is taken): FileWriteError.
    """
    path = Path(path)
    make_dirs(path.parent)
    if path.is_dir():
        raise FileWriteError(errno.EISDIR, f"cannot write {path}: it is a folder, not a file")
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        # Renaming over a device node, a FIFO or a link would silently replace it.
        kind = "a symbolic link" if stat.S_ISLNK(mode) else _file_kind(mode)
        raise FileWriteError(
            errno.EEXIST, f"cannot write {path}: it is {kind}, not a regular file; "
            "refusing to replace it"
        )
    try:
        descriptor, temporary = tempfile.mkstemp(
            dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"
        )
    except OSError as error:
        raise FileWriteError(
            error.errno, f"cannot write {path}: {describe_os_error(error)}"
        ) from error
    try:
        with os.fdopen(descriptor, "wb") as handle:
            os.fchmod(handle.fileno(), 0o666 & ~_umask())  # as open() would, not mkstemp's 0600
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        if replace:
            os.replace(temporary, path)
        else:
            _link_new(temporary, path)
    except OSError as error:
        Path(temporary).unlink(missing_ok=True)
        if isinstance(error, FileWriteError):
            raise
        kept = "; the previous version of the file is intact" if path.exists() else ""
        raise FileWriteError(
            error.errno, f"cannot write {path}: {describe_os_error(error)}{kept}"
        ) from error
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def _link_new(temporary: str, path: Path) -> None:
    """Put ``temporary`` at ``path`` unless ``path`` exists (FileWriteError then)."""
    appeared = FileWriteError(
        errno.EEXIST,
        f"cannot write {path}: a file of that name appeared while this command ran; it is "
        "kept (pass --overwrite to replace it)",
    )
    try:
        os.link(temporary, path)
    except FileExistsError:
        raise appeared from None
    except OSError as error:
        if error.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
            raise
        # A file system without hard links: check, then rename (a narrow window remains).
        if os.path.lexists(path):
            raise appeared from None
        os.replace(temporary, path)
        return
    Path(temporary).unlink()


@functools.cache
def _umask() -> int:
    mask = os.umask(0o022)  # reading the umask means setting it: put it straight back
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes, replace: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_write`)."""
    return atomic_write(path, lambda handle: handle.write(data), replace)


def atomic_write_text(path: str | os.PathLike, text: str, replace: bool = True) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`atomic_write`)."""
    return atomic_write_bytes(path, text.encode(), replace)


def write_json(path: str | os.PathLike, payload: Any) -> Path:
    """Write ``payload`` as indented JSON atomically; values JSON lacks become strings."""
    return atomic_write_text(path, json.dumps(payload, indent=2, default=str) + "\n")


def physical_memory_bytes() -> int | None:
    """This machine's physical memory, or None where the OS does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):
        return None


def check_fits_in_memory(nbytes: int, what: str, remedy: str) -> None:
    """Refuse to allocate more than this machine's physical memory: a clear error instead
    of an allocation that swaps the machine to a halt or gets the process killed."""
    memory = physical_memory_bytes()
    if memory is not None and nbytes > memory:
        raise TooLargeError(
            f"{what} needs {nbytes / 2**30:,.1f} GiB, more than this machine's "
            f"{memory / 2**30:,.1f} GiB of memory: {remedy}"
        )


MAX_COMPRESSION_RATIO = 400
"""The most an ``.npz`` member may claim to expand by (its uncompressed size over the bytes
it takes in the file), beyond :data:`NPZ_SLACK_BYTES`. spikectl's own files stay far below
(a few times); deflate cannot exceed about 1032, so a member claiming more than this is a
crafted or damaged file that would allocate gigabytes from megabytes."""
NPZ_SLACK_BYTES = 2**20


def npz_size_problem(source: str | os.PathLike | IO[bytes]) -> str | None:
    """What is wrong with the sizes an ``.npz`` file declares, or None: read from the
    array headers alone, before NumPy allocates anything. Each array's header must claim
    exactly the bytes its member holds, no more than :data:`MAX_COMPRESSION_RATIO` times
    what the member takes in the file, no Python objects, and all together no more than
    half this machine's memory."""
    import zipfile

    import numpy as np

    memory = physical_memory_bytes()
    total = 0
    with zipfile.ZipFile(source) as archive:
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                continue
            name = info.filename[: -len(".npy")]
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(member)
                else:
                    shape, _, dtype = np.lib.format.read_array_header_2_0(member)
                header_bytes = member.tell()
            if dtype.hasobject:
                return f"array {name!r} holds Python objects (refused)"
            claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
            total += claimed
            if claimed != info.file_size - header_bytes:
                return (f"is damaged: the header of array {name!r} claims shape "
                        f"{tuple(shape)} ({claimed:,} bytes), the file holds "
                        f"{info.file_size - header_bytes:,} bytes")  # fmt: skip
            if info.file_size > MAX_COMPRESSION_RATIO * info.compress_size + NPZ_SLACK_BYTES:
                return (f"is refused: array {name!r} claims {claimed:,} bytes from "
                        f"{info.compress_size:,} bytes in the file (more than "
                        f"{MAX_COMPRESSION_RATIO} times; spikectl never writes such a file)")
    if memory and 2 * total > memory:
        return (f"is refused: its arrays claim {total / 2**30:,.1f} GiB, more than half "
                f"this machine's {memory / 2**30:,.1f} GiB of memory")
    return None
