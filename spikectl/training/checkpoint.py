"""checkpoint.pt: a run's whole changing state, written atomically and restored exactly.

The file holds the run's part (the generator's state, the episode count, both clocks,
the metrics rows and baselines so far) and the learner's part (its ``state_dict``: for
the double-Q learner the online, target and auxiliary networks, the optimiser, the
replay buffer and its loss sums), with the config it was written for. It loads
weights-only and carries a checksum (``spikectl.training.torch_files``); a resumed run
continues bit-identically. A seed of a group writes the same file in its own directory.

Format 3 (since the training loop took learners as plug-ins). Format 2, the double-Q
trainer's before, is read too: its entries are the double-Q learner's. Format 1 is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spikectl.files import atomic_write_bytes, write_json
from spikectl.training.config import Experiment
from spikectl.training.run_files import (
    BASELINES_FILE,
    CHECKPOINT_FILE,
    CONFIG_FILE,
    RunDirError,
)
from spikectl.training.torch_files import (
    check_finite,
    first_line,
    load_torch_file,
    payload_checksum,
    peek_header,
    torch_bytes,
)

CHECKPOINT_FORMAT = "spikectl.checkpoint"
CHECKPOINT_VERSION = 3
READABLE_VERSIONS = (2, 3)
DQN_V2_ENTRIES = ("target", "predictor", "optimizer", "replay", "updates", "loss_sum",
                  "aux_loss_sum", "loss_count")  # fmt: skip
"""The double-Q learner's entries at the top level of a format-2 checkpoint (and
``online``, its acting network)."""


@dataclass
class RunState:
    """What the training loop keeps of one seed's run, apart from its learner."""

    rng: np.random.Generator
    """The run's one stream of draws: context choice, then the learner's (exploration,
    replay sampling), in the order the loop calls them."""
    episodes: int = 0
    wall_time_s: float = 0.0
    cpu_time_s: float = 0.0
    """Process CPU seconds (all threads) spent on this seed: its core-seconds."""
    metrics: list[dict] = field(default_factory=list)
    baselines: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_payload(self) -> dict[str, Any]:
        return {
            "rng": self.rng.bit_generator.state,
            "episodes": int(self.episodes),
            "wall_time_s": float(self.wall_time_s),
            "cpu_time_s": float(self.cpu_time_s),
            "metrics": [{key: _plain(value) for key, value in row.items()}
                        for row in self.metrics],  # fmt: skip
            "baselines": self.baselines,
        }

    @classmethod
    def from_payload(cls, entry: dict[str, Any], rng: np.random.Generator) -> RunState:
        """The saved state, its generator state restored into ``rng`` (the learner's too)."""
        rng.bit_generator.state = entry["rng"]
        return cls(
            rng=rng,
            episodes=entry["episodes"],
            wall_time_s=entry["wall_time_s"],
            # Checkpoints of spikectl before the cpu_time_s column have no CPU clock yet.
            cpu_time_s=float(entry.get("cpu_time_s", 0.0)),
            metrics=entry["metrics"],
            baselines=entry["baselines"],
        )


def _plain(value: Any) -> Any:
    """NumPy scalars as Python numbers (weights-only loading takes no NumPy objects)."""
    return value.item() if isinstance(value, np.generic) else value


def save_checkpoint(
    run_dir: Path, config: Experiment, state: RunState, learner_state: dict[str, Any]
) -> None:
    """Write checkpoint.pt atomically (then baselines.json); refuses (RunDirError) a
    learner state holding NaN or infinite values: the previous checkpoint stays."""
    from spikectl import __version__

    check_finite(learner_state, f"the learner's state in {run_dir}")
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "spikectl_version": __version__,
        "config": config.to_dict(),
        "learner": learner_state,
        "run": state.to_payload(),
    }
    payload["checksum"] = payload_checksum(payload)
    atomic_write_bytes(run_dir / CHECKPOINT_FILE, torch_bytes(payload))
    write_json(run_dir / BASELINES_FILE, state.baselines)


def read_checkpoint(path: Path, map_location: str = "cpu") -> dict[str, Any]:
    """The verified payload of a checkpoint file in format 3's layout: weights-only
    loaded, of a readable format, complete and matching its checksum; anything else is
    a RunDirError."""
    header = peek_header(path)
    if header.get("format") == CHECKPOINT_FORMAT and header.get("format_version") not in (
        None, *READABLE_VERSIONS,
    ):  # fmt: skip
        raise RunDirError(
            f"{path} has checkpoint format {header['format_version']} (written by spikectl "
            f"{header.get('spikectl_version', '?')}); this spikectl reads formats "
            f"{' and '.join(map(str, READABLE_VERSIONS))}: resume it with the version that "
            "wrote it, or start the run again"
        )
    payload = load_torch_file(path, "spikectl checkpoint", map_location)
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise RunDirError(f"{path} is not a spikectl checkpoint")
    version = payload.get("format_version")
    if version not in READABLE_VERSIONS:
        raise RunDirError(
            f"{path} has checkpoint format {version}; this spikectl reads formats "
            f"{' and '.join(map(str, READABLE_VERSIONS))}"
        )
    required = {"config": dict, "checksum": str}
    if version == 3:
        required |= {"learner": dict, "run": dict}
    else:
        required |= {"online": dict, "target": dict, "optimizer": dict, "replay": dict,
                     "updates": int, "loss_sum": float, "aux_loss_sum": float,
                     "loss_count": int}  # fmt: skip
    run_entries = {"rng": dict, "episodes": int, "wall_time_s": float, "metrics": list,
                   "baselines": dict}  # fmt: skip
    _check_entries(path, payload, required)
    checksum = payload.pop("checksum")
    if payload_checksum(payload) != checksum:
        raise RunDirError(f"{path} is damaged: its checksum does not match its contents")
    if version == 2:
        payload = _from_format_2(payload)
    _check_entries(path, payload["run"], run_entries)
    if not isinstance(payload["learner"].get("network"), dict):
        raise RunDirError(f"{path} is damaged: its learner has no 'network' entry")
    return payload


def _check_entries(path: Path, payload: dict, required: dict[str, type]) -> None:
    for key, kind in required.items():
        if key not in payload:
            raise RunDirError(f"{path} is damaged: it has no {key!r} entry")
        if not isinstance(payload[key], kind):
            raise RunDirError(f"{path} is damaged: its {key!r} entry is not a {kind.__name__}")


def _from_format_2(payload: dict[str, Any]) -> dict[str, Any]:
    """A format-2 checkpoint (the double-Q trainer's, one flat dict) in format 3's layout."""
    run_keys = ("rng", "episodes", "wall_time_s", "cpu_time_s", "metrics", "baselines")
    return {
        "config": payload["config"],
        "learner": {"network": payload["online"],
                    **{key: payload.get(key) for key in DQN_V2_ENTRIES}},  # fmt: skip
        "run": {key: payload[key] for key in run_keys if key in payload},
    }


def load_checkpoint(
    run_dir: Path, config: Experiment, learner, rng: np.random.Generator
) -> RunState:
    """Restore a run saved by ``save_checkpoint`` into ``learner`` and ``rng`` (the run's
    generator, which the learner draws from too); returns its RunState.
    Refuses one of another config, a damaged one, or one holding NaN or infinite values."""
    path = run_dir / CHECKPOINT_FILE
    if not path.exists():
        raise RunDirError(f"{run_dir} has no checkpoint yet")
    payload = read_checkpoint(path, map_location=config.train.device)
    if saved_config(payload["config"]) != config:
        raise RunDirError(f"{path} was written with another config than {run_dir / CONFIG_FILE}")
    check_finite(payload["learner"], str(path))
    try:
        learner.load_state_dict(payload["learner"])
        return RunState.from_payload(payload["run"], rng)
    except (RuntimeError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise RunDirError(f"{path} does not fit this run: {first_line(error)}") from None


def saved_config(values: dict[str, Any]) -> Experiment | None:
    """The config a checkpoint was written with (of any generation); None if it cannot
    be read."""
    try:
        return Experiment.from_dict(values)
    except (TypeError, ValueError):
        return None


def checkpoint_weights(path: Path) -> dict[str, torch.Tensor]:
    """The acting network's verified weights from a checkpoint file."""
    weights = read_checkpoint(path)["learner"]["network"]
    check_finite(weights, str(path))
    return weights
