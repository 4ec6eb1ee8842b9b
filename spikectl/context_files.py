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
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

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
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"
    )
    try:
        with os.fdopen(descriptor, "wb") as handle:
            np.savez_compressed(handle, metadata=np.array(json.dumps(header)), **arrays)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def read_npz(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and the header of a file written by :func:`write_npz`, checked."""
    if not path.exists():
        raise FileNotFoundError(f"context set file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as error:
        raise ContextFileError(f"{path} is not a readable spikectl context set: {error}") from error
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
    return arrays, metadata


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
