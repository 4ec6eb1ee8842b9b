"""Run directories, checked checkpoints and exact restore of a whole training state.

A run directory holds ``config.json`` (the resolved config), the two context sets,
``metrics.csv``, ``baselines.json``, ``checkpoint.pt`` (everything needed to resume:
online and target networks, optimiser, replay buffer, the generator's state, counters,
metrics so far), ``tensorboard/``, ``best_model.pt`` (the network of the evaluation with
the highest validation return so far, for runs with a validation set) and, at the end,
``model.pt`` (the online network's final state dict). Every file is written atomically
(``spikectl.files``), so a crash or a full disk at any moment leaves the previous
version intact.

``checkpoint.pt`` and ``model.pt`` load with ``torch.load(..., weights_only=True)``:
they hold tensors and plain data only (dicts, lists, numbers, strings), never pickled
Python objects, so a crafted file cannot run code. Each carries a SHA-256 checksum of
its whole content, verified on load like the context sets': flipped bytes are refused,
never used. A lock file (``.spikectl.lock``) keeps two processes from training in one
run directory at once.
"""

from __future__ import annotations

import contextlib
import csv
import functools
import hashlib
import io
import json
import math
import os
import pickle
import pickletools
import shutil
import zipfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spikectl.files import (
    FileWriteError,
    atomic_write_bytes,
    atomic_write_text,
    describe_os_error,
    make_dirs,
    write_json,
)
from spikectl.training.config import Experiment
from spikectl.training.replay import EpisodeReplay

__all__ = [
    "RunDirError",
    "TrainingState",
    "load_checkpoint",
    "forget_best_model_after",
    "load_model_weights",
    "prepare_run_dir",
    "read_config",
    "read_metrics",
    "save_checkpoint",
    "save_model",
    "write_metrics",
]

CHECKPOINT_FORMAT = "spikectl.checkpoint"
CHECKPOINT_VERSION = 2
"""2: weights-only loadable (no NumPy objects), with a checksum, the auxiliary head. Version 1
is refused."""
MODEL_FORMAT = "spikectl.model"
MODEL_VERSION = 1
CONFIG_FILE = "config.json"
CHECKPOINT_FILE = "checkpoint.pt"
MODEL_FILE = "model.pt"
BEST_MODEL_FILE = "best_model.pt"
METRICS_FILE = "metrics.csv"
BASELINES_FILE = "baselines.json"
LOCK_FILE = ".spikectl.lock"
UNSTARTED_LEFTOVERS = (
    METRICS_FILE, BASELINES_FILE, "train_contexts.npz", "test_contexts.npz", "tensorboard",
    "learning_curve.png", BEST_MODEL_FILE,
)  # fmt: skip
"""What a run that stopped before its first checkpoint may have written besides its
config; a restart from step 0 removes it."""


class RunDirError(RuntimeError):
    """A run directory that cannot be used as asked (holds another run, incompatible,
    damaged, locked by another process, ...)."""


@dataclass
class TrainingState:
    """Everything of a run that changes, apart from networks, optimiser and buffer."""

    rng: np.random.Generator
    """Exploration, context choice and replay sampling all draw from this one stream."""
    episodes: int = 0
    updates: int = 0
    loss_sum: float = 0.0
    aux_loss_sum: float = 0.0
    loss_count: int = 0
    wall_time_s: float = 0.0
    cpu_time_s: float = 0.0
    """Process CPU seconds (all threads): the run's core-seconds."""
    metrics: list[dict] = field(default_factory=list)
    baselines: dict[str, dict[str, float]] = field(default_factory=dict)


def check_device(device: str) -> None:
    """Refuse a Torch device this machine does not have, before anything is written."""
    try:
        parsed = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(f"device must be cpu, cuda or cuda:N, got {device!r}") from None
    if parsed.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(
                f"device {device!r} asks for CUDA, which this machine (or this PyTorch build) "
                "does not have: use --device cpu"
            )
        if parsed.index is not None and parsed.index >= torch.cuda.device_count():
            raise ValueError(
                f"device {device!r}: this machine has {torch.cuda.device_count()} CUDA device(s)"
            )
    elif parsed.type == "mps":
        if not torch.backends.mps.is_available():
            raise ValueError(f"device {device!r}: MPS is not available on this machine")
    elif parsed.type != "cpu":
        raise ValueError(f"device must be cpu, cuda or cuda:N, got {device!r}")


@contextlib.contextmanager
def run_lock(run_dir: Path) -> Iterator[None]:
    """Hold the run directory's lock file for the block; another process holding it is
    an error naming that process. The lock dies with its process (even on SIGKILL)."""
    import fcntl

    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError(f"{run_dir} is a file, not a run directory: choose another --run-dir")
    created = not run_dir.exists()
    make_dirs(run_dir)
    path = run_dir / LOCK_FILE
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
            raise RunDirError(
                f"another process (pid {owner}) is training in {run_dir}: wait for it to "
                "finish or stop it; two runs must never write one directory"
            ) from None
        os.ftruncate(descriptor, 0)
        os.pwrite(descriptor, f"{os.getpid()}\n".encode(), 0)
        try:
            yield
        finally:
            if created and {p.name for p in run_dir.iterdir()} == {LOCK_FILE}:
                # Nothing was started: leave no empty directory behind.
                path.unlink(missing_ok=True)
                with contextlib.suppress(OSError):
                    run_dir.rmdir()
    finally:
        os.close(descriptor)


def locked_run(train: Callable[..., Any]) -> Callable[..., Any]:
    """Decorate ``train(config, run_dir, resume=False)`` to hold the run directory's
    lock for the whole run."""

    @functools.wraps(train)
    def locked(config: Experiment, run_dir: str | os.PathLike, *args, **kwargs):
        with run_lock(Path(run_dir)):
            return train(config, run_dir, *args, **kwargs)

    return locked


def prepare_run_dir(config: Experiment, run_dir: Path, resume: bool) -> bool:
    """Create a new run directory, or check that ``run_dir`` holds this run to resume.

    Returns whether there is a checkpoint to resume from. A run that stopped before its
    first checkpoint (killed, out of disk, a bad file) is started again from step 0,
    whether it is given with ``resume`` or as a new run with the same config.
    """
    check_device(config.train.device)
    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError(f"{run_dir} is a file, not a run directory: choose another --run-dir")
    config_path = run_dir / CONFIG_FILE
    has_config = config_path.exists()
    has_checkpoint = (run_dir / CHECKPOINT_FILE).exists()
    if resume:
        if not has_config:
            raise RunDirError(f"{run_dir} holds no run to resume (no {CONFIG_FILE})")
        if read_config(run_dir) != config:
            raise RunDirError(f"the config does not match the run saved in {run_dir}")
        if has_checkpoint:
            remove_temporaries(run_dir)
            return True
        _clear_unstarted(run_dir)
        return False
    if has_config:
        if has_checkpoint or (run_dir / MODEL_FILE).exists():
            raise RunDirError(
                f"{run_dir} already holds a run: resume it with `spikectl train --resume "
                f"{run_dir}` or choose another --run-dir"
            )
        if read_config(run_dir) != config:
            raise RunDirError(
                f"{run_dir} holds a run with another config that stopped before its first "
                "checkpoint: choose another --run-dir, or delete that directory"
            )
        _clear_unstarted(run_dir)  # the same run, never checkpointed: start it again
        return False
    if run_dir.exists() and any(p.name != LOCK_FILE for p in run_dir.iterdir()):
        raise RunDirError(f"{run_dir} is not empty and holds no spikectl run: choose another")
    make_dirs(run_dir)
    write_json(config_path, config.to_dict())
    return False


def _clear_unstarted(run_dir: Path) -> None:
    """Remove what a run wrote before its first checkpoint, and the temporary files of
    interrupted writes; the config stays."""
    for name in UNSTARTED_LEFTOVERS:
        path = run_dir / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)
    remove_temporaries(run_dir)


def remove_temporaries(run_dir: Path) -> None:
    """Remove the temporary files of writes a kill interrupted (we hold the lock, so no
    write of ours is under way)."""
    for temporary in run_dir.glob(".*.tmp"):
        temporary.unlink(missing_ok=True)


def read_config(run_dir: Path) -> Experiment:
    """The resolved config saved in a run directory."""
    path = Path(run_dir) / CONFIG_FILE
    try:
        values = json.loads(path.read_text())
    except FileNotFoundError:
        raise RunDirError(f"{run_dir} is not a spikectl run directory (no {CONFIG_FILE})") from None
    except OSError as error:
        raise RunDirError(f"cannot read {path}: {describe_os_error(error)}") from error
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise RunDirError(f"{path} is not a valid spikectl config: {error}") from error
    if not isinstance(values, dict):
        raise RunDirError(f"{path} is not a valid spikectl config: not a JSON object")
    try:
        return Experiment.from_dict(values)
    except (TypeError, ValueError) as error:
        raise RunDirError(f"{path} is not a valid spikectl config: {error}") from error


def write_metrics(run_dir: Path, rows: list[dict], fields: tuple[str, ...]) -> None:
    """Rewrite metrics.csv from all rows (small; rewriting keeps it exact after a resume)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({key: _format(row.get(key, math.nan)) for key in fields})
    atomic_write_text(run_dir / METRICS_FILE, buffer.getvalue())


def read_metrics(run_dir: Path) -> list[dict[str, float]]:
    path = Path(run_dir) / METRICS_FILE
    try:
        with open(path, newline="") as handle:
            return [
                {key: float(value) for key, value in row.items()} for row in csv.DictReader(handle)
            ]
    except FileNotFoundError:
        raise
    except OSError as error:
        raise RunDirError(f"cannot read {path}: {describe_os_error(error)}") from error
    except (ValueError, TypeError, UnicodeDecodeError, csv.Error) as error:
        raise RunDirError(f"{path} is damaged: {error}") from error


def _format(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    return str(value)


def payload_checksum(payload: Any) -> str:
    """SHA-256 over a payload of tensors and plain data: every tensor's dtype, shape and
    bytes, and every other value's repr, in order. Equal payloads, equal checksums."""
    digest = hashlib.sha256()
    _digest(payload, digest)
    return digest.hexdigest()


def _digest(value: Any, digest: Any) -> None:
    if isinstance(value, torch.Tensor):
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


def check_finite(tensors: Mapping[str, torch.Tensor], what: str) -> None:
    """Refuse NaN or infinite floating-point values (a diverged run), naming one."""
    for name, tensor in tensors.items():
        if torch.is_tensor(tensor) and tensor.is_floating_point():
            if not torch.isfinite(tensor).all():
                raise RunDirError(
                    f"{what}: {name} holds NaN or infinite values (training diverged); "
                    "refusing to use or save them"
                )


def _peek_header(path: Path) -> dict[str, Any]:
    """The plain strings and numbers that follow the top-level keys ``format``,
    ``format_version`` and ``spikectl_version`` of a torch file, read from its pickle
    opcodes without unpickling anything (so an old or crafted file runs no code)."""
    wanted = {"format", "format_version", "spikectl_version"}
    found: dict[str, Any] = {}
    try:
        with zipfile.ZipFile(path) as archive:
            name = next(n for n in archive.namelist() if n.endswith("data.pkl"))
            data = archive.read(name)
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
        if path.stat().st_size == 0:
            raise RunDirError(f"{path} is not a readable {what}: the file is empty")
        if not zipfile.is_zipfile(path):
            raise RunDirError(f"{path} is not a readable {what}: not a PyTorch (zip) file")
        return torch.load(path, map_location=map_location, weights_only=True)
    except RunDirError:
        raise
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


def save_checkpoint(
    run_dir: Path,
    config: Experiment,
    state: TrainingState,
    online: torch.nn.Module,
    target: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    replay: EpisodeReplay,
    predictor: torch.nn.Module | None = None,
) -> None:
    """Write checkpoint.pt atomically with everything ``load_checkpoint`` restores.

    Refuses (RunDirError) to save networks that hold NaN or infinite values: the
    previous checkpoint stays.
    """
    from spikectl import __version__

    check_finite(online.state_dict(), f"the online network of {run_dir}")
    check_finite(target.state_dict(), f"the target network of {run_dir}")
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "spikectl_version": __version__,
        "arch": config.agent.arch,
        "config": config.to_dict(),
        "online": online.state_dict(),
        "target": target.state_dict(),
        "predictor": None if predictor is None else predictor.state_dict(),
        "optimizer": optimizer.state_dict(),
        **state_payload(state, replay),
    }
    payload["checksum"] = payload_checksum(payload)
    atomic_write_bytes(run_dir / CHECKPOINT_FILE, torch_bytes(payload))
    write_json(run_dir / BASELINES_FILE, state.baselines)


def state_payload(state: TrainingState, replay: EpisodeReplay) -> dict[str, Any]:
    """One run's changing state and replay buffer as plain data and tensors (what a
    weights-only load takes back); :func:`restore_state` inverts it."""
    return {
        "replay": {
            name: torch.from_numpy(np.ascontiguousarray(value))
            if isinstance(value, np.ndarray) else int(value)
            for name, value in replay.state_dict().items()
        },
        "rng": state.rng.bit_generator.state,
        "episodes": int(state.episodes),
        "updates": int(state.updates),
        "loss_sum": float(state.loss_sum),
        "aux_loss_sum": float(state.aux_loss_sum),
        "loss_count": int(state.loss_count),
        "wall_time_s": float(state.wall_time_s),
        "cpu_time_s": float(state.cpu_time_s),
        "metrics": [{key: _plain(value) for key, value in row.items()} for row in state.metrics],
        "baselines": state.baselines,
    }  # fmt: skip


def restore_state(entry: dict[str, Any], replay: EpisodeReplay) -> TrainingState:
    """Fill ``replay`` from a :func:`state_payload` entry and return its TrainingState."""
    replay.load_state_dict(
        {name: value.numpy() if torch.is_tensor(value) else value
         for name, value in entry["replay"].items()}
    )  # fmt: skip
    rng = np.random.default_rng()
    rng.bit_generator.state = entry["rng"]
    return TrainingState(
        rng=rng,
        episodes=entry["episodes"],
        updates=entry["updates"],
        loss_sum=entry["loss_sum"],
        aux_loss_sum=entry["aux_loss_sum"],
        loss_count=entry["loss_count"],
        wall_time_s=entry["wall_time_s"],
        # Checkpoints of spikectl before the cpu_time_s column have no CPU clock yet.
        cpu_time_s=float(entry.get("cpu_time_s", 0.0)),
        metrics=entry["metrics"],
        baselines=entry["baselines"],
    )


def _plain(value: Any) -> Any:
    """NumPy scalars as Python numbers (weights-only loading takes no NumPy objects)."""
    return value.item() if isinstance(value, np.generic) else value


def read_checkpoint(path: Path, map_location: str = "cpu") -> dict[str, Any]:
    """The verified payload of a checkpoint file: weights-only loaded, of this format
    version, complete and matching its checksum; anything else is a RunDirError."""
    header = _peek_header(path)
    if header.get("format") == CHECKPOINT_FORMAT and header.get("format_version") not in (
        None, CHECKPOINT_VERSION,
    ):  # fmt: skip
        raise RunDirError(
            f"{path} has checkpoint format {header['format_version']} (written by spikectl "
            f"{header.get('spikectl_version', '?')}); this spikectl reads format "
            f"{CHECKPOINT_VERSION}: resume it with the version that wrote it, or start the "
            "run again"
        )
    payload = load_torch_file(path, "spikectl checkpoint", map_location)
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise RunDirError(f"{path} is not a spikectl checkpoint")
    if payload.get("format_version") != CHECKPOINT_VERSION:
        raise RunDirError(
            f"{path} has checkpoint format {payload.get('format_version')}; this spikectl "
            f"reads format {CHECKPOINT_VERSION}"
        )
    required = {
        "arch": str, "config": dict, "online": dict, "target": dict, "optimizer": dict,
        "replay": dict, "rng": dict, "episodes": int, "updates": int, "loss_sum": float,
        "aux_loss_sum": float, "loss_count": int, "wall_time_s": float, "metrics": list,
        "baselines": dict,
        "checksum": str,
    }  # fmt: skip
    for key, kind in required.items():
        if key not in payload:
            raise RunDirError(f"{path} is damaged: it has no {key!r} entry")
        if not isinstance(payload[key], kind):
            raise RunDirError(f"{path} is damaged: its {key!r} entry is not a {kind.__name__}")
    checksum = payload.pop("checksum")
    if payload_checksum(payload) != checksum:
        raise RunDirError(f"{path} is damaged: its checksum does not match its contents")
    return payload


def load_checkpoint(
    run_dir: Path,
    config: Experiment,
    online: torch.nn.Module,
    target: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    replay: EpisodeReplay,
    predictor: torch.nn.Module | None = None,
) -> TrainingState:
    """Restore a run saved by ``save_checkpoint``; refuse one of another version or
    config, a damaged one, or one whose networks hold NaN or infinite values."""
    path = run_dir / CHECKPOINT_FILE
    if not path.exists():
        raise RunDirError(f"{run_dir} has no checkpoint yet")
    payload = read_checkpoint(path, map_location=config.train.device)
    if payload["arch"] != config.agent.arch or saved_config(payload["config"]) != config:
        raise RunDirError(
            f"{path} was written for arch {payload['arch']!r} with another config than "
            f"{run_dir / CONFIG_FILE}"
        )
    check_finite(payload["online"], str(path))
    check_finite(payload["target"], str(path))
    try:
        online.load_state_dict(payload["online"])
        target.load_state_dict(payload["target"])
        if predictor is not None:
            predictor.load_state_dict(payload["predictor"])
        optimizer.load_state_dict(payload["optimizer"])
        return restore_state(payload, replay)
    except (RuntimeError, ValueError, KeyError, TypeError) as error:
        raise RunDirError(f"{path} does not fit this run: {first_line(error)}") from None


def saved_config(values: dict[str, Any]) -> Experiment | None:
    """The config a checkpoint was written with (a flat one before the tree); None if
    it cannot be read."""
    try:
        return Experiment.from_dict(values)
    except (TypeError, ValueError):
        return None


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
    path = run_dir / file_name
    weights = network.state_dict()
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


def forget_best_model_after(run_dir: Path, episode: int) -> None:
    """Remove a ``best_model.pt`` taken after ``episode`` (a run killed after its last
    checkpoint may have written one): the resumed run writes it again when it gets
    there, so the file always belongs to the evaluations in metrics.csv. A damaged
    file is removed too, for the same reason."""
    path = run_dir / BEST_MODEL_FILE
    if not path.exists():
        return
    try:
        taken_at = model_episode(path)
    except RunDirError:
        taken_at = None
    if taken_at is None or taken_at > episode:
        path.unlink()


def load_model_weights(path: Path) -> dict[str, torch.Tensor]:
    """The verified state dict of a model.pt: weights-only loaded, checksum checked,
    finite. Damage, foreign files and pickled objects are RunDirErrors."""
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
    if payload_checksum(dict(weights)) != header.get("checksum"):
        raise RunDirError(f"{path} is damaged: its checksum does not match its contents")
    check_finite(weights, str(path))
    return weights


def checkpoint_weights(path: Path) -> dict[str, torch.Tensor]:
    """The online network's verified weights from a checkpoint file."""
    weights = read_checkpoint(path)["online"]
    check_finite(weights, str(path))
    return weights
