"""Run directories, atomic checkpoints and exact restore of a whole training state.

A run directory holds ``config.json`` (the resolved config), the two context sets,
``metrics.csv``, ``baselines.json``, ``checkpoint.pt`` (everything needed to resume:
online and target networks, optimiser, replay buffer, the generator's state, counters,
metrics so far), ``tensorboard/`` and, at the end, ``model.pt`` (the online network's
state dict). Every file is written to a temporary name and renamed into place, so a
crash or a full disk at any moment leaves the previous version intact.
"""

from __future__ import annotations

import csv
import errno
import io
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spikectl.training.config import TrainConfig
from spikectl.training.replay import EpisodeReplay

CHECKPOINT_FORMAT = "spikectl.checkpoint"
CHECKPOINT_VERSION = 2
CONFIG_FILE = "config.json"
CHECKPOINT_FILE = "checkpoint.pt"
MODEL_FILE = "model.pt"
METRICS_FILE = "metrics.csv"
BASELINES_FILE = "baselines.json"


class RunDirError(RuntimeError):
    """A run directory that cannot be used as asked (holds another run, incompatible, ...)."""


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
    metrics: list[dict] = field(default_factory=list)
    baselines: dict[str, dict[str, float]] = field(default_factory=dict)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file and a rename; a full disk is a
    clear error and leaves any previous file untouched."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except OSError as error:
        Path(temporary).unlink(missing_ok=True)
        if error.errno == errno.ENOSPC:
            raise RunDirError(
                f"no space left on the device while writing {path}; the previous version of "
                "the file is intact: free some space and resume the run"
            ) from error
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def prepare_run_dir(config: TrainConfig, run_dir: Path, resume: bool) -> None:
    """Create a new run directory, or check that ``run_dir`` holds this run to resume."""
    config_path = run_dir / CONFIG_FILE
    if resume:
        if not config_path.exists():
            raise RunDirError(f"{run_dir} holds no run to resume (no {CONFIG_FILE})")
        saved = read_config(run_dir)
        if saved != config:
            raise RunDirError(f"the config does not match the run saved in {run_dir}")
        return
    if run_dir.exists() and any(run_dir.iterdir()):
        if config_path.exists():
            raise RunDirError(
                f"{run_dir} already holds a run: resume it with `spikectl train --resume "
                f"{run_dir}` or choose another --run-dir"
            )
        raise RunDirError(f"{run_dir} is not empty and holds no spikectl run: choose another")
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(config_path, json.dumps(config.to_dict(), indent=2) + "\n")


def read_config(run_dir: Path) -> TrainConfig:
    """The resolved config saved in a run directory."""
    path = Path(run_dir) / CONFIG_FILE
    try:
        return TrainConfig.from_dict(json.loads(path.read_text()))
    except FileNotFoundError:
        raise RunDirError(f"{run_dir} is not a spikectl run directory (no {CONFIG_FILE})") from None
    except (json.JSONDecodeError, TypeError, ValueError) as error:
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
    with open(Path(run_dir) / METRICS_FILE, newline="") as handle:
        return [{key: float(value) for key, value in row.items()} for row in csv.DictReader(handle)]


def _format(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    return str(value)


def _torch_bytes(payload: Any) -> bytes:
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return buffer.getvalue()


def save_checkpoint(
    run_dir: Path,
    config: TrainConfig,
    state: TrainingState,
    online: torch.nn.Module,
    target: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    replay: EpisodeReplay,
    predictor: torch.nn.Module | None = None,
) -> None:
    """Write checkpoint.pt atomically with everything ``load_checkpoint`` restores."""
    from spikectl import __version__

    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "spikectl_version": __version__,
        "arch": config.arch,
        "config": config.to_dict(),
        "online": online.state_dict(),
        "target": target.state_dict(),
        "predictor": None if predictor is None else predictor.state_dict(),
        "optimizer": optimizer.state_dict(),
        "replay": replay.state_dict(),
        "rng": state.rng.bit_generator.state,
        "episodes": state.episodes,
        "updates": state.updates,
        "loss_sum": state.loss_sum,
        "aux_loss_sum": state.aux_loss_sum,
        "loss_count": state.loss_count,
        "wall_time_s": state.wall_time_s,
        "metrics": state.metrics,
        "baselines": state.baselines,
    }
    atomic_write_bytes(run_dir / CHECKPOINT_FILE, _torch_bytes(payload))
    atomic_write_text(run_dir / BASELINES_FILE, json.dumps(state.baselines, indent=2) + "\n")


def load_checkpoint(
    run_dir: Path,
    config: TrainConfig,
    online: torch.nn.Module,
    target: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    replay: EpisodeReplay,
    predictor: torch.nn.Module | None = None,
) -> TrainingState:
    """Restore a run saved by ``save_checkpoint``; refuse one of another version or config."""
    path = run_dir / CHECKPOINT_FILE
    if not path.exists():
        raise RunDirError(
            f"{run_dir} has no checkpoint yet (the run stopped before its first one): "
            "delete the directory and start again"
        )
    try:
        payload = torch.load(path, map_location=config.device, weights_only=False)
    except Exception as error:  # torch raises many types for a damaged file
        raise RunDirError(f"{path} is not a readable checkpoint: {error}") from error
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise RunDirError(f"{path} is not a spikectl checkpoint")
    if payload.get("format_version") != CHECKPOINT_VERSION:
        raise RunDirError(
            f"{path} has checkpoint format {payload.get('format_version')}; this spikectl "
            f"reads format {CHECKPOINT_VERSION}"
        )
    if payload["arch"] != config.arch or payload["config"] != config.to_dict():
        raise RunDirError(
            f"{path} was written for arch {payload['arch']!r} with another config than "
            f"{run_dir / CONFIG_FILE}"
        )
    online.load_state_dict(payload["online"])
    target.load_state_dict(payload["target"])
    if predictor is not None:
        predictor.load_state_dict(payload["predictor"])
    optimizer.load_state_dict(payload["optimizer"])
    replay.load_state_dict(payload["replay"])
    rng = np.random.default_rng()
    rng.bit_generator.state = payload["rng"]
    state = TrainingState(
        rng=rng,
        episodes=payload["episodes"],
        updates=payload["updates"],
        loss_sum=payload["loss_sum"],
        aux_loss_sum=payload["aux_loss_sum"],
        loss_count=payload["loss_count"],
        wall_time_s=payload["wall_time_s"],
        metrics=payload["metrics"],
        baselines=payload["baselines"],
    )
    return state


def save_model(run_dir: Path, network: torch.nn.Module) -> Path:
    """The final weights: a plain state dict, loadable with ``torch.load``."""
    path = run_dir / MODEL_FILE
    atomic_write_bytes(path, _torch_bytes(network.state_dict()))
    return path
