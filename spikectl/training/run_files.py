"""Run directories: their files, their lock, their config and metrics.

A run directory holds ``config.json`` (the resolved config), the context sets,
``metrics.csv``, ``baselines.json``, ``checkpoint.pt`` (``spikectl.training.checkpoint``),
``tensorboard/``, ``best_model.pt``, ``machine.json`` (``spikectl.training.machine``) and,
at the end, ``model.pt``. Every file is written
atomically (``spikectl.files``), so a crash or a full disk at any moment leaves the
previous version intact. A lock file (``.spikectl.lock``) keeps two processes from
training in one run directory at once.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import torch

from spikectl.file_kinds import FileKind, describe, identify
from spikectl.files import (
    atomic_write_text,
    describe_os_error,
    make_dirs,
    read_json_file,
    read_text_file,
    write_json,
)
from spikectl.locks import LOCK_FILE, folder_lock
from spikectl.training.config import Experiment

CONFIG_FILE = "config.json"
CHECKPOINT_FILE = "checkpoint.pt"
MODEL_FILE = "model.pt"
BEST_MODEL_FILE = "best_model.pt"
METRICS_FILE = "metrics.csv"
BASELINES_FILE = "baselines.json"
MACHINE_FILE = "machine.json"
RUN_FILE_NAMES = (
    CONFIG_FILE, CHECKPOINT_FILE, MODEL_FILE, BEST_MODEL_FILE, METRICS_FILE, BASELINES_FILE,
    MACHINE_FILE, "train_contexts.npz", "test_contexts.npz", "val_contexts.npz",
    "learning_curve.png", "best_model.set-aside.pt", LOCK_FILE,
)  # fmt: skip
"""The files of a run directory: never an output of another command."""
CLOCK_FIELDS = ("wall_time_s", "cpu_time_s", "eval_cpu_time_s")
"""The clocks of metrics.csv and of a checkpoint's runs: the only values a bit-identical
rerun may change."""
UNSTARTED_LEFTOVERS = (
    METRICS_FILE, BASELINES_FILE, "train_contexts.npz", "test_contexts.npz", "tensorboard",
    "learning_curve.png", BEST_MODEL_FILE, MACHINE_FILE,
)  # fmt: skip
"""What a run that stopped before its first checkpoint may have written besides its
config; a restart from step 0 removes it."""


class RunDirError(RuntimeError):
    """A run directory that cannot be used as asked (holds another run, incompatible,
    damaged, locked by another process, ...)."""


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
    a RunDirError naming that process. The lock dies with its process (even on SIGKILL)."""
    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError(f"{run_dir} is a file, not a run directory: choose another --run-dir")
    with folder_lock(run_dir, "training", busy=RunDirError):
        yield


def check_run_path(run_dir: Path, flag: str = "--run-dir") -> None:
    """Refuse, before anything is made, a run directory that could not be completed: a
    name that is not UTF-8 (its files, TensorBoard's among them, record it as UTF-8
    text), a path through a file, or a folder this process may not write in. ValueError
    naming ``flag``."""
    try:
        str(run_dir).encode("utf-8")
    except UnicodeEncodeError:
        shown = os.fsencode(run_dir).decode("ascii", "backslashreplace")
        raise ValueError(
            f"{flag} {shown}: the name is not valid UTF-8 (a run records its directory in "
            "UTF-8 files): choose a name in UTF-8"
        ) from None
    existing = Path(run_dir)
    while not os.path.lexists(existing) and existing != existing.parent:
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        what = "is a file" if existing == Path(run_dir) else f"lies in {existing}, a file"
        raise ValueError(f"{flag} {run_dir}: it {what}, not a folder")
    if existing.is_dir() and not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {run_dir}: {existing} is not writable by this user")


def prepare_run_dir(config: Experiment, run_dir: Path, resume: bool) -> bool:
    """Create a new run directory, or check that ``run_dir`` holds this run to resume.

    Returns whether there is a checkpoint to resume from. A run that stopped before its
    first checkpoint (killed, out of disk, a bad file) is started again from step 0,
    whether it is given with ``resume`` or as a new run with the same config. The caller
    (``training.run.train_runs``) has checked the device before any directory is touched.
    """
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
        if _holds_only_a_config(run_dir):
            # A start that failed before anything else was written (bad contexts, an
            # impossible task): the corrected command takes the directory over.
            write_json(config_path, config.to_dict())
            return False
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


def remove_unstarted(made: list[Path]) -> None:
    """Remove the run directories in ``made`` (made by this process) that hold no
    evaluation and no checkpoint yet: what a run refused while it set up leaves. Seed
    directories first, the group's last (it holds them)."""
    for path in reversed(made):
        if not path.is_dir() or any(
            (run_dir / name).exists()
            for run_dir in (path, *path.glob("seed=*"))
            for name in (METRICS_FILE, CHECKPOINT_FILE)
        ):
            continue
        shutil.rmtree(path, ignore_errors=True)


def _holds_only_a_config(run_dir: Path) -> bool:
    """Whether ``run_dir`` holds config.json and nothing else of a run (its lock and
    temporary files aside): what a start that failed before its contexts leaves."""
    return all(
        path.name in (CONFIG_FILE, LOCK_FILE, MACHINE_FILE) or path.name.endswith(".tmp")
        for path in run_dir.iterdir()
    )


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
    kind = identify(run_dir)
    if kind not in (FileKind.RUN_DIR, FileKind.FOLDER, FileKind.MISSING):
        raise RunDirError(
            f"{describe(run_dir, kind)}; a run directory is a folder spikectl train wrote "
            "(its config.json and the run's files)"
        )
    path = Path(run_dir) / CONFIG_FILE
    try:
        values = read_json_file(path)
    except FileNotFoundError:
        raise RunDirError(f"{run_dir} is not a spikectl run directory (no {CONFIG_FILE})") from None
    except OSError as error:
        raise RunDirError(f"cannot read {path}: {describe_os_error(error)}") from error
    except ValueError as error:  # bad JSON or text, too large, nested too deeply
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


REQUIRED_METRICS = ("episode", "env_steps", "train_return", "test_return", "wall_time_s")
"""The columns every metrics.csv spikectl wrote has, and that its readers use."""


def read_metrics(run_dir: Path) -> list[dict[str, float]]:
    """The rows of a run's metrics.csv as numbers; one lacking a column of
    :data:`REQUIRED_METRICS` (renamed by hand) or holding text is a RunDirError."""
    path = Path(run_dir) / METRICS_FILE
    try:
        handle = io.StringIO(read_text_file(path), newline="")
        reader = csv.DictReader(handle)
        missing = [name for name in REQUIRED_METRICS if name not in (reader.fieldnames or ())]
        if missing:
            raise RunDirError(f"{path} is damaged: it has no column {', '.join(missing)} "
                              f"(its columns: {', '.join(reader.fieldnames or ())})")  # fmt: skip
        return [{key: float(value) for key, value in row.items()} for row in reader]
    except RunDirError:
        raise
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
