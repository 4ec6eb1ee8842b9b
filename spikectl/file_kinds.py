"""What kind of spikectl file a path is, told without loading it.

Every command that reads a run, a network, a policy or a context set takes a path, and
users hand one kind where another belongs (a compiled policy to ``--init-from``, a
checkpoint to ``realtime``). The library that would then fail (PyTorch, NumPy) speaks of
its own internals ("[enforce fail at inline_container.cc:180]"). :func:`identify` looks
at the path (a folder's marker files, a zip archive's member names, a ``.npz`` header,
the format strings of a torch file's pickle read as opcodes, never unpickled) and
:func:`wrong_kind` makes the one line that names the kind found and the kind expected.

This module sits at the bottom of the layering with ``spikectl.files``: the readers of
every layer use it.
"""

from __future__ import annotations

import enum
import json
import math
import os
import pickletools
import stat
import zipfile
from collections.abc import Callable, Iterable
from pathlib import Path

from spikectl.files import MAX_TEXT_FILE_BYTES, open_regular_file

MAX_HEADER_BYTES = 2**20
"""The most of a ``.npz`` header member read to tell its format (far above any header)."""


class FileKind(enum.Enum):
    """The kinds of path spikectl reads, each with how a message names it."""

    RUN_DIR = "a spikectl run directory"
    SEED_GROUP = "a spikectl seed-group directory (one run directory per seed inside)"
    MODEL = "a trained network's weights (model.pt)"
    BEST_MODEL = "a run's best network on validation (best_model.pt)"
    CHECKPOINT = "a training checkpoint (checkpoint.pt)"
    POLICY = "a compiled policy file (.npz from export_policy)"
    CONTEXT_SET = "a context set file (.npz)"
    TORCH_FILE = "a PyTorch file that spikectl did not write"
    NPZ_FILE = "a NumPy .npz file that is neither a compiled policy nor a context set"
    FOLDER = "a folder that holds no spikectl run"
    MISSING = "a path that does not exist"
    SPECIAL = "not a regular file (a FIFO, a device or a socket)"
    OTHER = "a file that is not a spikectl file"


MODEL_FORMAT = "spikectl.model"
CHECKPOINT_FORMAT = "spikectl.checkpoint"
POLICY_FORMAT = "spikectl.CompiledPolicy"
CONTEXT_SET_FORMAT = "spikectl.ContextSet"
"""The format names the writers put in their headers (each module's own constant equals
its name here; ``tests/test_file_kinds.py`` checks that)."""


class WrongFileKindError(ValueError):
    """A path of one kind given where another kind belongs (one line naming both)."""


def identify(path: str | os.PathLike) -> FileKind:
    """The kind of ``path``; reads at most a file's zip directory and one small member,
    and never opens anything that is not a regular file."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return FileKind.MISSING
    except OSError:
        return FileKind.OTHER
    if stat.S_ISDIR(mode):
        if (path / "group.json").is_file():
            return FileKind.SEED_GROUP
        return FileKind.RUN_DIR if (path / "config.json").is_file() else FileKind.FOLDER
    if not stat.S_ISREG(mode):
        return FileKind.SPECIAL
    try:
        with open_regular_file(path) as handle:
            if not zipfile.is_zipfile(handle):
                return FileKind.OTHER
            handle.seek(0)
            with zipfile.ZipFile(handle) as archive:
                return _zip_kind(archive)
    except (OSError, zipfile.BadZipFile, ValueError, EOFError, RuntimeError):
        return FileKind.OTHER


def describe(path: str | os.PathLike, kind: FileKind | None = None) -> str:
    """``path`` and what it is, e.g. ``pol.npz is a compiled policy file (...)``."""
    kind = identify(path) if kind is None else kind
    if kind is FileKind.MISSING:
        return f"{path} does not exist"
    return f"{path} is {kind.value}"


def wrong_kind(path: str | os.PathLike, kind: FileKind, expected: str) -> WrongFileKindError:
    """The error for ``path`` (of ``kind``) given where ``expected`` belongs: ``expected``
    says what the reader takes (e.g. ``"--init-from takes a run directory, ..."``)."""
    return WrongFileKindError(f"{describe(path, kind)}; {expected}")


RECOGNISED = frozenset({
    FileKind.RUN_DIR, FileKind.SEED_GROUP, FileKind.MODEL, FileKind.BEST_MODEL,
    FileKind.CHECKPOINT, FileKind.POLICY, FileKind.CONTEXT_SET,
})  # fmt: skip
"""The kinds spikectl writes: one of them where another belongs is named as such. Any
other path goes to the reader, whose own message says what is wrong with it (damaged,
empty, not a zip archive)."""


def refuse_other_kinds(
    path: str | os.PathLike,
    accepted: Iterable[FileKind],
    expected: str,
    error: Callable[[str], Exception] = WrongFileKindError,
) -> None:
    """Raise ``error`` (one line: the kind found, then ``expected``) when ``path`` is a
    spikectl file of a kind not in ``accepted``; anything else passes to the reader."""
    kind = identify(path)
    if kind in RECOGNISED and kind not in set(accepted):
        raise error(f"{describe(path, kind)}; {expected}")


def _zip_kind(archive: zipfile.ZipFile) -> FileKind:
    infos = archive.infolist()
    pickles = [info for info in infos if info.filename.endswith("/data.pkl")]
    if pickles:
        return _torch_kind(archive, pickles[0])
    names = {info.filename for info in infos}
    if "metadata.npy" in names and all(name.endswith(".npy") for name in names):
        header = _npz_header(archive, archive.getinfo("metadata.npy"))
        if header == POLICY_FORMAT:
            return FileKind.POLICY
        if header == CONTEXT_SET_FORMAT:
            return FileKind.CONTEXT_SET
    if names and all(name.endswith(".npy") for name in names):
        return FileKind.NPZ_FILE
    return FileKind.OTHER


def _npz_header(archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> str | None:
    """The ``format`` of a ``.npz`` file's JSON header (its ``metadata`` array), or None.
    The array's own header is read first and its size bounded before any data is: a
    crafted header claiming gigabytes allocates nothing."""
    if info.file_size > MAX_HEADER_BYTES:
        return None
    import numpy as np

    with archive.open(info) as member:
        try:
            version = np.lib.format.read_magic(member)
            read_header = (
                np.lib.format.read_array_header_1_0
                if version == (1, 0)
                else np.lib.format.read_array_header_2_0
            )
            shape, _, dtype = read_header(member)
            count = math.prod(shape)
            if dtype.kind != "U" or count != 1 or dtype.itemsize > MAX_HEADER_BYTES:
                return None
            text = str(np.frombuffer(member.read(dtype.itemsize), dtype=dtype, count=1)[0])
        except (ValueError, TypeError, EOFError):
            return None
    try:
        header = json.loads(text)
    except (ValueError, RecursionError):
        return None
    value = header.get("format") if isinstance(header, dict) else None
    return value if isinstance(value, str) else None


def _torch_kind(archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> FileKind:
    """A torch file's kind from the strings in its pickle, read as opcodes: the format
    names spikectl's writers put in it, and ``episode`` (a best model records its own)."""
    if info.file_size > MAX_TEXT_FILE_BYTES:
        return FileKind.TORCH_FILE
    strings = set()
    try:
        for opcode, argument, _ in pickletools.genops(archive.read(info)):
            if opcode.name in ("BINUNICODE", "SHORT_BINUNICODE", "UNICODE") and len(argument) < 64:
                strings.add(argument)
    except (ValueError, EOFError, zipfile.BadZipFile):
        return FileKind.TORCH_FILE
    if CHECKPOINT_FORMAT in strings:
        return FileKind.CHECKPOINT
    if MODEL_FORMAT in strings:
        return FileKind.BEST_MODEL if "episode" in strings else FileKind.MODEL
    return FileKind.TORCH_FILE
