"""checkpoint.pt: the whole changing state of a run or a seed group, written atomically
and restored exactly.

One format for a single run (in its run directory) and a seed group (in the group's
directory): per seed its config and the run's part of its state (the generator's state,
the episode count, the clocks, the metrics rows and baselines so far), and the learners'
state (``LearnerGroup.state_dict``: for looped learners each seed's ``state_dict``; for
the double-Q learner the online, target and auxiliary networks, the optimiser, the replay
buffer and its loss sums). It loads weights-only and carries a checksum
(``spikectl.training.torch_files``); a resumed run continues bit-identically, and one
file keeps a group's seeds in lockstep.

Format 3 (since the training loop took learners as plug-ins). Format 2, a single run of
the double-Q trainer before, is read too. Format 1 is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spikectl.file_kinds import FileKind, refuse_other_kinds
from spikectl.files import atomic_write_bytes, write_json
from spikectl.training.best_model import LEGACY, check_kept, fitting_weights
from spikectl.training.checkpoint_checks import (
    check_entries,
    check_learner_state,
    check_optimizers,
    check_runs,
)
from spikectl.training.config import Experiment
from spikectl.training.run_files import (
    BASELINES_FILE,
    CHECKPOINT_FILE,
    RunDirError,
)
from spikectl.training.torch_files import (
    check_finite,
    first_line,
    load_torch_file,
    payload_checksum,
    peek_header,
    torch_bytes,
    verify_checksum,
)
from spikectl.version import __version__

CHECKPOINT_FORMAT = "spikectl.checkpoint"
CHECKPOINT_VERSION = 3
READABLE_VERSIONS = (2, 3)
"""Format 2 is read because docs/training.md promises that a checkpoint of the double-Q
trainer from before learners were plug-ins still resumes (tests/test_golden.py)."""
FORMAT_2_RUN_ENTRIES = ("rng", "episodes", "wall_time_s", "cpu_time_s", "metrics", "baselines")
FORMAT_2_OTHER_ENTRIES = ("format", "format_version", "spikectl_version", "arch", "config",
                          "online")  # fmt: skip
"""A format-2 checkpoint's top-level entries besides the run's; every other one is the
learner's state (and ``online`` its acting network)."""


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
    eval_cpu_time_s: float = 0.0
    """The part of ``cpu_time_s`` spent in the greedy evaluations (every set, every
    ``eval_every_episodes``): core-seconds that measure the run, not train it."""
    metrics: list[dict] = field(default_factory=list)
    baselines: dict[str, dict[str, float]] = field(default_factory=dict)
    contexts: dict[str, str] = field(default_factory=dict)
    """The checksum of each context set the run plays (train, test, validation), so that
    a resume refuses sets swapped for others (empty in checkpoints before they were kept)."""
    best_model: Any = None
    """The best network on validation so far (``best_model.kept_network``: its episode and
    weights), None before the first validation, ``best_model.LEGACY`` in checkpoints of
    spikectl before they kept it: a resume restores best_model.pt from it."""

    def to_payload(self) -> dict[str, Any]:
        return {
            "rng": self.rng.bit_generator.state,
            "episodes": int(self.episodes),
            "wall_time_s": float(self.wall_time_s),
            "cpu_time_s": float(self.cpu_time_s),
            "eval_cpu_time_s": float(self.eval_cpu_time_s),
            "metrics": [
                {key: _plain(value) for key, value in row.items()} for row in self.metrics
            ],  # fmt: skip
            "baselines": self.baselines,
            "contexts": dict(self.contexts),
            "best_model": self.best_model,
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
            # ... and those before 2026-11-24 no evaluation clock (NaN: not measured).
            eval_cpu_time_s=float(entry.get("eval_cpu_time_s", math.nan)),
            metrics=entry["metrics"],
            baselines=entry["baselines"],
            contexts={str(k): str(v) for k, v in dict(entry.get("contexts", {})).items()},
            best_model=entry.get("best_model", LEGACY),
        )


def _plain(value: Any) -> Any:
    """NumPy scalars as Python numbers (weights-only loading takes no NumPy objects)."""
    return value.item() if isinstance(value, np.generic) else value


def save_checkpoint(
    where: Path,
    configs: list[Experiment],
    states: list[RunState],
    learners_state: dict[str, Any],
    run_dirs: list[Path],
    stacked: bool = False,
) -> None:
    """Write ``where/checkpoint.pt`` atomically (then each seed's baselines.json);
    refuses (RunDirError) a learner state holding NaN or infinite values: the previous
    checkpoint stays."""
    check_finite(learners_state, f"the learners' state in {where}")
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "spikectl_version": __version__,
        "configs": [config.to_dict() for config in configs],
        "stacked": bool(stacked),
        "learners": learners_state,
        "runs": [state.to_payload() for state in states],
    }
    payload["checksum"] = payload_checksum(payload)
    atomic_write_bytes(where / CHECKPOINT_FILE, torch_bytes(payload))
    for state, run_dir in zip(states, run_dirs, strict=True):
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
    refuse_other_kinds(path, (FileKind.CHECKPOINT,), "a checkpoint is a run's "
                       "checkpoint.pt", RunDirError)  # fmt: skip
    payload = load_torch_file(path, "spikectl checkpoint", map_location)
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise RunDirError(f"{path} is not a spikectl checkpoint")
    version = payload.get("format_version")
    if version not in READABLE_VERSIONS:
        raise RunDirError(
            f"{path} has checkpoint format {version}; this spikectl reads formats "
            f"{' and '.join(map(str, READABLE_VERSIONS))}"
        )
    if version == 3:
        required = {"configs": list, "stacked": bool, "learners": dict, "runs": list}
    else:
        required = {"config": dict, "online": dict, "target": dict, "optimizer": dict,
                    "replay": dict, "updates": int, "loss_sum": float, "aux_loss_sum": float,
                    "loss_count": int}  # fmt: skip
    _check_entries(path, payload, {**required, "checksum": str})
    checksum = payload.pop("checksum")
    verify_checksum(payload, checksum, path)
    if version == 2:
        payload = _from_format_2(payload)
    elif isinstance(payload["runs"], list):
        check_entries(path, payload)
    if len(payload["runs"]) != len(payload["configs"]) or not payload["runs"]:
        raise RunDirError(f"{path} is damaged: it has {len(payload['runs'])} runs for "
                          f"{len(payload['configs'])} configs")  # fmt: skip
    run_entries = {"rng": dict, "episodes": int, "wall_time_s": float, "metrics": list,
                   "baselines": dict}  # fmt: skip
    for run in payload["runs"]:
        if not isinstance(run, dict):
            raise RunDirError(f"{path} is damaged: a run entry is not a dict")
        _check_entries(path, run, run_entries)
        check_kept(run.get("best_model", LEGACY), path)
    return payload


def _check_entries(path: Path, payload: dict, required: dict[str, type]) -> None:
    for key, kind in required.items():
        if key not in payload:
            raise RunDirError(f"{path} is damaged: it has no {key!r} entry")
        if not isinstance(payload[key], kind):
            raise RunDirError(f"{path} is damaged: its {key!r} entry is not a {kind.__name__}")


def _from_format_2(payload: dict[str, Any]) -> dict[str, Any]:
    """A format-2 checkpoint (the double-Q trainer's, one flat dict) in format 3's layout."""
    run_keys = FORMAT_2_RUN_ENTRIES
    learner = {"network": payload["online"]}
    learner.update(
        (key, value) for key, value in payload.items()
        if key not in run_keys and key not in FORMAT_2_OTHER_ENTRIES
    )  # fmt: skip
    return {
        "configs": [payload["config"]],
        "stacked": False,
        "learners": {"seeds": [learner]},
        "runs": [{key: payload[key] for key in run_keys if key in payload}],
    }


def load_checkpoint(
    where: Path,
    configs: list[Experiment],
    learners,
    rngs: list[np.random.Generator],
    stacked: bool = False,
) -> list[RunState]:
    """Restore ``where/checkpoint.pt`` into ``learners`` and the seeds' generators
    ``rngs`` (which the learners draw from too); returns each seed's RunState. Refuses
    one written for other configs, a damaged one, or one holding NaN or infinite values."""
    path = where / CHECKPOINT_FILE
    if not path.exists():
        raise RunDirError(f"{where} has no checkpoint yet")
    payload = read_checkpoint(path, map_location=configs[0].train.device)
    if [saved_config(values) for values in payload["configs"]] != configs:
        raise RunDirError(f"{path} was written with other configs than {where}'s")
    if payload["stacked"] != stacked:
        raise RunDirError(
            f"{path} was written by a {'stacked' if payload['stacked'] else 'looped'} group, "
            f"this one is {'stacked' if stacked else 'looped'}"
        )
    check_finite(payload["learners"], str(path))
    check_runs(path, payload["runs"], [config.total_episodes for config in configs])
    check_learner_state(path, payload["learners"], learners.state_dict())
    try:
        learners.load_state_dict(payload["learners"])
        runs = zip(payload["runs"], rngs, strict=True)
        states = [RunState.from_payload(run, rng) for run, rng in runs]
        for k, state in enumerate(states):
            if isinstance(state.best_model, dict):
                fitting_weights(state.best_model, learners.network(k))
    except (RuntimeError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise RunDirError(f"{path} does not fit this run: {first_line(error)}") from None
    check_optimizers(path, learners)
    return states


def saved_config(values: dict[str, Any]) -> Experiment | None:
    """The config a checkpoint was written with (of any generation); None if it cannot
    be read."""
    try:
        return Experiment.from_dict(values)
    except (TypeError, ValueError):
        return None


def checkpoint_weights(path: Path) -> dict[str, torch.Tensor]:
    """A single run's acting network's verified weights from its checkpoint file."""
    payload = read_checkpoint(path)
    try:
        (seed,) = payload["learners"]["seeds"]
        weights = seed["network"]
    except (KeyError, TypeError, ValueError):
        raise RunDirError(
            f"{path} is not a single run's checkpoint with a network (a seed group's is in "
            "its group directory: evaluate a seed's model.pt)"
        ) from None
    if not isinstance(weights, dict):
        raise RunDirError(f"{path} is damaged: its network is not a state dict")
    check_finite(weights, str(path))
    return weights
