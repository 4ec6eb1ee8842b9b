"""Torch files that are safe to load: weights-only, checksummed, finite, one clear error.

``checkpoint.pt``, ``model.pt`` and ``best_model.pt`` load with
``torch.load(..., weights_only=True)``: they hold tensors and plain data only (dicts,
lists, numbers, strings), never pickled Python objects, so a crafted file cannot run
code. Each carries a SHA-256 checksum of its whole content, verified on load like the
context sets': flipped bytes are refused, never used.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import pickletools
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from spikectl.file_kinds import FileKind, refuse_other_kinds
from spikectl.files import (
    MAX_TEXT_FILE_BYTES,
    NotARegularFileError,
    atomic_write_bytes,
    open_regular_file,
)
from spikectl.training.run_files import MODEL_FILE, RunDirError

MODEL_FORMAT = "spikectl.model"
MODEL_VERSION = 1


def payload_checksum(payload: Any) -> str:
    """SHA-256 over a payload of tensors and plain data: every tensor's dtype, shape and
    bytes, and every other value's repr, in order. Equal payloads, equal checksums."""
    digest = hashlib.sha256()
    _digest(payload, digest)
    return digest.hexdigest()


def verify_checksum(payload: Any, checksum: Any, path: Path) -> None:
    """Refuse (RunDirError) a loaded payload whose checksum is not ``checksum``, or that
    holds what no spikectl file holds (sparse tensors, objects, nesting too deep)."""
    try:
        actual = payload_checksum(payload)
    except (TypeError, RecursionError) as error:
        raise RunDirError(f"{path} is damaged: {first_line(error)}") from None
    if actual != checksum:
        raise RunDirError(f"{path} is damaged: its checksum does not match its contents")


def _digest(value: Any, digest: Any) -> None:
    if isinstance(value, torch.Tensor):
        if value.layout != torch.strided:
            raise TypeError(f"cannot checksum a {value.layout} tensor (dense tensors only)")
        tensor = value.detach().cpu().contiguous()
        digest.update(f"T{tensor.dtype}{tuple(tensor.shape)}".encode())
        digest.update(tensor.reshape(-1).view(torch.uint8).numpy())
    elif isinstance(value, Mapping):
        digest.update(f"D{len(value)}".encode())
        for key, item in value.items():
            digest.update(f"K{key!r}".encode())
            _digest(item, digest)
    elif isinstance(value, (list, tuple)):
        digest.update(f"L{type(value).__name__}{len(value)}".encode())
        for item in value:
            _digest(item, digest)
    elif value is None or isinstance(value, (bool, int, float, str)):
        digest.update(f"V{value!r}".encode())
    else:
        raise TypeError(f"cannot checksum a {type(value).__name__} (tensors and plain data only)")


def torch_bytes(payload: Any) -> bytes:
    """``torch.save(payload)`` into bytes, for the atomic writer."""
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return buffer.getvalue()


def check_finite(tensors: Mapping[str, Any], what: str) -> None:
    """Refuse NaN or infinite floating-point values (a diverged run), naming one; nested
    mappings and lists (a learner's state, an optimiser's) are searched too."""
    for name, value in tensors.items():
        if isinstance(value, Mapping):
            check_finite(value, what)
        elif isinstance(value, (list, tuple)):
            check_finite(dict(enumerate(value)), what)
        elif torch.is_tensor(value) and value.is_floating_point():
            if not torch.isfinite(value).all():
                raise RunDirError(
                    f"{what}: {name} holds NaN or infinite values (training diverged); "
                    "refusing to use or save them"
                )


def peek_header(path: Path) -> dict[str, Any]:
    """The plain strings and numbers that follow the top-level keys ``format``,
    ``format_version`` and ``spikectl_version`` of a torch file, read from its pickle
    opcodes without unpickling anything (so an old or crafted file runs no code)."""
    wanted = {"format", "format_version", "spikectl_version"}
    found: dict[str, Any] = {}
    try:
        with open_regular_file(path) as handle, zipfile.ZipFile(handle) as archive:
            info = next(i for i in archive.infolist() if i.filename.endswith("data.pkl"))
            if info.file_size > MAX_TEXT_FILE_BYTES:
                return found  # no header to peek at; the full load refuses the file
            data = archive.read(info)
        previous = None
        for opcode, argument, _ in pickletools.genops(data):
            if opcode.name in ("BINPUT", "LONG_BINPUT", "PUT", "MEMOIZE"):
                continue  # memo bookkeeping between a key and its value
            if previous in wanted and previous not in found and isinstance(argument, (str, int)):
                found[previous] = argument
            previous = argument if opcode.name in ("BINUNICODE", "SHORT_BINUNICODE") else None
    except (zipfile.BadZipFile, StopIteration, ValueError, OSError, EOFError):
        pass
    return found


def load_torch_file(path: Path, what: str, map_location: str = "cpu") -> Any:
    """``torch.load(path, weights_only=True)`` with every failure as one RunDirError
    line naming the file and the problem."""
    if path.is_dir():
        raise RunDirError(f"{path} is a folder, not a {what}")
    try:
        # One guarded open (a FIFO, a device or /dev/zero is refused on the descriptor);
        # torch reads the very handle that was checked.
        with open_regular_file(path) as handle:
            if os.fstat(handle.fileno()).st_size == 0:
                raise RunDirError(f"{path} is not a readable {what}: the file is empty")
            if not zipfile.is_zipfile(handle):
                raise RunDirError(f"{path} is not a readable {what}: not a PyTorch (zip) file")
            handle.seek(0)
            return torch.load(handle, map_location=map_location, weights_only=True)
    except RunDirError:
        raise
    except NotARegularFileError as error:
        raise RunDirError(f"{path} is not a readable {what}: {error.strerror}") from None
    except pickle.UnpicklingError as error:
        if "GLOBAL" in str(error) or "global" in str(error):
            raise RunDirError(
                f"{path} is refused: it holds pickled Python objects that could run code "
                f"when loaded (nothing in it was run); a {what} holds only tensors and data"
            ) from None
        raise RunDirError(f"{path} is not a readable {what}: {first_line(error)}") from None
    except Exception as error:  # torch raises many types for a damaged file
        raise RunDirError(f"{path} is not a readable {what}: {first_line(error)}") from None


def first_line(error: BaseException) -> str:
    """An exception's first message line (its type name when it has no message)."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


def save_model(
    run_dir: Path,
    network: torch.nn.Module,
    file_name: str = MODEL_FILE,
    episode: int | None = None,
) -> Path:
    """A network's weights (the final ones by default): a plain state dict, loadable with
    ``torch.load(path, weights_only=True)`` and ``load_state_dict``. Its
    ``_metadata["spikectl"]`` entry (which ``load_state_dict`` ignores) holds the format,
    the checksum of the weights and, if given, the ``episode`` they were taken at.
    Refuses NaN or infinite weights."""
    return save_weights(run_dir / file_name, network.state_dict(), episode)


def save_weights(path: Path, weights: dict[str, torch.Tensor], episode: int | None = None) -> Path:
    """Write a state dict (as ``state_dict()`` returns it) in ``save_model``'s format."""
    check_finite(weights, f"the network saved as {path}")
    header = {
        "format": MODEL_FORMAT,
        "format_version": MODEL_VERSION,
        "checksum": payload_checksum(dict(weights)),
    }
    if episode is not None:
        header["episode"] = int(episode)
    weights._metadata["spikectl"] = header
    atomic_write_bytes(path, torch_bytes(weights))
    return path


def model_episode(path: Path) -> int | None:
    """The episode a saved model was taken at (None if the file does not record one)."""
    weights = load_model_weights(path)
    episode = weights._metadata["spikectl"].get("episode")
    return episode if isinstance(episode, int) and not isinstance(episode, bool) else None


def load_model_weights(path: Path) -> dict[str, torch.Tensor]:
    """The verified state dict of a model.pt: weights-only loaded, checksum checked,
    finite. Damage, foreign files and pickled objects are RunDirErrors."""
    refuse_other_kinds(
        path, (FileKind.MODEL, FileKind.BEST_MODEL),
        "a model file is a run's model.pt or best_model.pt", RunDirError,
    )  # fmt: skip
    weights = load_torch_file(path, "spikectl model", "cpu")
    metadata = getattr(weights, "_metadata", None) or {}
    header = metadata.get("spikectl") if isinstance(metadata, Mapping) else None
    if not isinstance(weights, dict) or not isinstance(header, dict):
        raise RunDirError(
            f"{path} is not a spikectl model of this version (no spikectl entry in its "
            "metadata; a model.pt written before checksums cannot be verified: train again)"
        )
    if header.get("format") != MODEL_FORMAT or header.get("format_version") != MODEL_VERSION:
        raise RunDirError(
            f"{path} has model format {header.get('format')!r} version "
            f"{header.get('format_version')}; this spikectl reads {MODEL_FORMAT!r} "
            f"version {MODEL_VERSION}"
        )
    if not all(torch.is_tensor(value) for value in weights.values()):
        raise RunDirError(f"{path} is damaged: it holds entries that are not tensors")
    verify_checksum(dict(weights), header.get("checksum"), path)
    check_finite(weights, str(path))
    return weights
