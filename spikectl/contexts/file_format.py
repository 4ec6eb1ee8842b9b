"""The ``.npz`` file format of context sets: atomic writes, checked reads.

A file holds named arrays and one JSON header (``metadata``) with the format name and
version. Version 1 is the paper's contexts (``weights``, ``targets``, ``patterns``,
``witnesses``); version 2 adds the optional arrays of the context-level extensions
(``hidden``, ``thresholds_mV``, ``time_constants_ms``, ``synaptic_scale``). A set
without extensions is still written as version 1, byte for byte as before, and both
versions are read. :class:`spikectl.ContextSet` builds on these two functions.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from spikectl.file_kinds import FileKind, refuse_other_kinds
from spikectl.files import atomic_write, check_regular_file, npz_size_problem

FORMAT_NAME = "spikectl.ContextSet"
FORMAT_VERSION = 1
"""The version written for sets without extensions."""
EXTENDED_FORMAT_VERSION = 2
"""The version written for sets with context-level extensions."""
READABLE_VERSIONS = (FORMAT_VERSION, EXTENDED_FORMAT_VERSION)

REQUIRED_ARRAYS = frozenset({"weights", "targets", "patterns", "witnesses"})
EXTENSION_ARRAYS = frozenset({"hidden", "thresholds_mV", "time_constants_ms", "synaptic_scale"})


class ContextFileError(ValueError):
    """A context-set file that is unreadable, damaged, foreign or of another version."""


def write_npz(path: Path, arrays: dict[str, np.ndarray], metadata: dict[str, Any]) -> Path:
    """Write arrays and a JSON header to one ``.npz`` file, atomically.

    The version is 1 unless an extension array or field is present. A crash never
    leaves half a file: the data go to a temporary file in the same folder first.
    """
    extended = bool(EXTENSION_ARRAYS & set(arrays)) or bool(metadata.get("extensions"))
    header = {
        "format": FORMAT_NAME,
        "format_version": EXTENDED_FORMAT_VERSION if extended else FORMAT_VERSION,
        **metadata,
    }
    if not header.get("extensions"):
        header.pop("extensions", None)

    def write(handle) -> None:
        np.savez_compressed(handle, metadata=np.array(json.dumps(header)), **arrays)

    return atomic_write(path, write)


def read_npz(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and the header of a file written by :func:`write_npz`, checked.

    Before anything is allocated, every array's header is compared with the size of
    its data in the file, so a damaged or crafted header (shapes claiming terabytes)
    is refused instead of allocated. Pickled objects are never loaded.
    """
    if not path.exists():
        raise FileNotFoundError(f"context set file not found: {path}")
    if path.is_dir():
        raise ContextFileError(f"{path} is a folder, not a context set file")
    try:
        check_regular_file(path)
    except OSError as error:
        raise ContextFileError(f"{path} is not a context set file: {error.strerror}") from None
    refuse_other_kinds(path, (FileKind.CONTEXT_SET,), "a context set is an .npz written by "
                       "ContextSet.save or spikectl contexts", ContextFileError)  # fmt: skip
    try:
        _check_array_sizes(path)
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except ContextFileError:
        raise
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, zlib.error) as error:
        problem = str(error).splitlines()[0] if str(error) else type(error).__name__
        if path.stat().st_size == 0:
            problem = "the file is empty"
        raise ContextFileError(
            f"{path} is not a readable spikectl context set: {problem}"
        ) from error
    if "metadata" not in arrays or not REQUIRED_ARRAYS <= set(arrays):
        raise ContextFileError(
            f"{path} is not a spikectl context set (arrays {sorted(arrays)}, expected "
            f"{sorted(REQUIRED_ARRAYS | {'metadata'})})"
        )
    metadata = _parse_metadata(path, arrays.pop("metadata"))
    allowed = REQUIRED_ARRAYS | (EXTENSION_ARRAYS if metadata["format_version"] >= 2 else set())
    unexpected = sorted(set(arrays) - allowed)
    if unexpected:
        raise ContextFileError(
            f"{path} is not a spikectl context set of version {metadata['format_version']} "
            f"(unexpected arrays {unexpected})"
        )
    _check_array_shapes(path, arrays, metadata)
    return arrays, metadata


_ARRAY_LAYOUTS = {
    "weights": (("S", "n", "n"), "iu", "integer"),
    "targets": (("S",), "iu", "integer"),
    "patterns": (("S", "N"), "biu", "bool"),
    "witnesses": (("S", "N"), "iu", "integer"),
    "hidden": (("S", "h"), "iu", "integer"),
    "thresholds_mV": (("S", "n"), "f", "float"),
    "time_constants_ms": (("S", "n"), "f", "float"),
    "synaptic_scale": (("S", "n", "n"), "f", "float"),
}
"""Each array's shape (S contexts, n neurons, N steps, h hidden neurons), the dtype kinds
it may have and how a message names them."""
_DIMENSION_NAMES = {"S": "contexts", "n": "neurons", "N": "steps", "h": "hidden neurons"}


def _check_array_shapes(path: Path, arrays: dict[str, np.ndarray], metadata: dict) -> None:
    """Refuse, in one line naming the array and the shape it must have, an array whose
    shape or dtype does not fit the set the header describes (its size, n and episode
    length; where the header lacks one, the first array that has it)."""
    sizes: dict[str, int] = {}
    for key, header_key in (("S", "size"), ("n", "n_neurons"), ("N", "episode_length")):
        value = metadata.get(header_key)
        if type(value) is int and value >= 1:
            sizes[key] = value
    for name, (dimensions, kinds, dtype_name) in _ARRAY_LAYOUTS.items():
        if name not in arrays:
            continue
        array = arrays[name]
        if array.ndim == len(dimensions):
            for dimension, length in zip(dimensions, array.shape, strict=True):
                sizes.setdefault(dimension, length)
        expected = tuple(sizes.get(dimension, -1) for dimension in dimensions)
        if array.shape != expected or array.dtype.kind not in kinds:
            described = ", ".join(
                f"{sizes[d]} {_DIMENSION_NAMES[d]}" for d in dict.fromkeys(dimensions) if d in sizes
            )
            shown = str(expected).replace("-1", "?")
            raise ContextFileError(
                f"{path} is damaged: its array {name} is {array.dtype} of shape {array.shape}; "
                f"a set of {described} has {name} of shape {shown} ({dtype_name})"
            )


def _check_array_sizes(path: Path) -> None:
    """Refuse arrays whose header claims more data than the file holds, or more memory
    than the machine has, before NumPy allocates them (``files.npz_size_problem``)."""
    problem = npz_size_problem(path)
    if problem is not None:
        separator = " " if problem.startswith("is ") else ": "
        raise ContextFileError(f"{path}{separator}{problem}")


def _parse_metadata(path: Path, raw: np.ndarray) -> dict[str, Any]:
    try:
        metadata = json.loads(str(raw))
    except (json.JSONDecodeError, TypeError) as error:
        raise ContextFileError(f"{path} has an unreadable header: {error}") from error
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT_NAME:
        raise ContextFileError(f"{path} is not a spikectl context set (no {FORMAT_NAME} header)")
    version = metadata.get("format_version")
    if version not in READABLE_VERSIONS:
        raise ContextFileError(
            f"{path} has context-set format version {version}; this spikectl reads versions "
            f"{', '.join(map(str, READABLE_VERSIONS))}"
        )
    return metadata
