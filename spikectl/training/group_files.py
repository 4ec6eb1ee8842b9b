"""The files of a seed group (``spikectl.training.ensemble``): its description and its
one checkpoint.

A group directory holds ``group.json`` (the seeds' configs and run directories) and
``group_checkpoint.pt``: the stacked online, target and auxiliary networks, the stacked
optimiser, and per seed its replay buffer, generator state, counters, metrics and
baselines. One file written atomically (``spikectl.files``) keeps the seeds in lockstep:
a kill at any moment leaves the previous checkpoint of the whole group. Like
``checkpoint.pt`` it loads weights-only and carries a SHA-256 checksum of its content.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from spikectl.files import atomic_write_bytes, make_dirs, write_json
from spikectl.training.checkpoint import (
    CONFIG_FILE,
    LOCK_FILE,
    RunDirError,
    TrainingState,
    check_finite,
    first_line,
    load_torch_file,
    payload_checksum,
    prepare_run_dir,
    read_config,
    remove_temporaries,
    restore_state,
    saved_config,
    state_payload,
    torch_bytes,
)
from spikectl.training.config import Experiment

GROUP_FILE = "group.json"
GROUP_CHECKPOINT_FILE = "group_checkpoint.pt"
GROUP_FORMAT = "spikectl.group_checkpoint"
GROUP_VERSION = 1


def group_description(configs: list[Experiment], run_dirs: list[Path], group_dir: Path) -> dict:
    """What group.json holds: the seeds' configs and run directories (relative to the
    group directory when inside it)."""
    return {
        "format": "spikectl.group",
        "configs": [config.to_dict() for config in configs],
        "run_dirs": [os.path.relpath(Path(d).resolve(), group_dir.resolve()) for d in run_dirs],
    }


def read_group(group_dir: str | os.PathLike) -> dict:
    """The description a group directory holds (group.json)."""
    if not (Path(group_dir) / GROUP_FILE).exists():
        raise RunDirError(f"{group_dir} holds no seed group (no {GROUP_FILE})")
    return _read_description(Path(group_dir))


def _read_description(group_dir: Path) -> dict:
    path = group_dir / GROUP_FILE
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as error:
        raise RunDirError(f"{path} is not a valid seed-group file: {first_line(error)}") from None


def _normalised(description: dict, group_dir: Path) -> dict:
    """A saved group.json with its configs in today's form (flat ones before the tree)."""
    try:
        configs = [Experiment.from_dict(values).to_dict() for values in description["configs"]]
    except (KeyError, TypeError, ValueError) as error:
        raise RunDirError(
            f"{group_dir / GROUP_FILE} is not a valid seed-group file: {first_line(error)}"
        ) from None
    return json.loads(json.dumps({**description, "configs": configs}))


def prepare_group(
    configs: list[Experiment], run_dirs: list[Path], group_dir: Path, resume: bool
) -> bool:
    """Create the group and its seeds' run directories, or check that ``group_dir`` holds
    this group to resume. Returns whether there is a group checkpoint to resume from; a
    group that stopped before its first checkpoint starts again from step 0."""
    description = json.loads(json.dumps(group_description(configs, run_dirs, group_dir)))
    has_file = (group_dir / GROUP_FILE).exists()
    has_checkpoint = (group_dir / GROUP_CHECKPOINT_FILE).exists()
    if has_file and _normalised(_read_description(group_dir), group_dir) != description:
        raise RunDirError(
            f"{group_dir} holds another seed group (its {GROUP_FILE} has other configs or "
            "seeds): choose another --run-dir"
        )
    if resume and not has_file:
        raise RunDirError(f"{group_dir} holds no seed group to resume (no {GROUP_FILE})")
    if has_checkpoint:
        if not resume:
            raise RunDirError(
                f"{group_dir} already holds a seed group: resume it with `spikectl train "
                f"--resume {group_dir}` or choose another --run-dir"
            )
        for config, run_dir in zip(configs, run_dirs, strict=True):
            if not (run_dir / CONFIG_FILE).exists():
                raise RunDirError(f"{run_dir}, a seed of the group, has lost its {CONFIG_FILE}")
            if read_config(run_dir) != config:
                raise RunDirError(f"the config in {run_dir} does not match its seed group")
            if (run_dir / "checkpoint.pt").exists():
                raise RunDirError(f"{run_dir} holds a single run's checkpoint, not a group seed")
            remove_temporaries(run_dir)
        remove_temporaries(group_dir)
        return True
    if not has_file:
        members = {Path(d).resolve() for d in run_dirs}
        if group_dir.exists() and any(
            p.name != LOCK_FILE and p.resolve() not in members for p in group_dir.iterdir()
        ):
            raise RunDirError(f"{group_dir} is not empty and holds no seed group: choose another")
    for config, run_dir in zip(configs, run_dirs, strict=True):
        # A seed's directory from a group that never checkpointed starts again too.
        prepare_run_dir(config, run_dir, resume=(run_dir / CONFIG_FILE).exists())
        if (run_dir / "checkpoint.pt").exists() or (run_dir / "model.pt").exists():
            raise RunDirError(f"{run_dir} already holds a run: it cannot join a seed group")
    make_dirs(group_dir)
    write_json(group_dir / GROUP_FILE, description)
    return False


def save_group_checkpoint(
    group_dir, configs, run_dirs, states, online, target, predictor, optimizer, replays
) -> None:
    """Write group_checkpoint.pt atomically (then each seed's baselines.json); refuses
    networks holding NaN or infinite values (the previous checkpoint stays)."""
    from spikectl import __version__

    check_finite(online.stacked_state(), f"the online networks of {group_dir}")
    check_finite(target.stacked_state(), f"the target networks of {group_dir}")
    payload = {
        "format": GROUP_FORMAT,
        "format_version": GROUP_VERSION,
        "spikectl_version": __version__,
        "configs": [config.to_dict() for config in configs],
        "online": online.stacked_state(),
        "target": target.stacked_state(),
        "predictor": None if predictor is None else predictor.stacked_state(),
        "optimizer": optimizer.state_dict(),
        "seeds": [
            state_payload(state, replay) for state, replay in zip(states, replays, strict=True)
        ],
    }
    payload["checksum"] = payload_checksum(payload)
    atomic_write_bytes(group_dir / GROUP_CHECKPOINT_FILE, torch_bytes(payload))
    for state, run_dir in zip(states, run_dirs, strict=True):
        write_json(run_dir / "baselines.json", state.baselines)


def load_group_checkpoint(
    group_dir, configs, online, target, predictor, optimizer, replays
) -> list[TrainingState]:
    """Restore a group saved by ``save_group_checkpoint``; refuse a damaged one, one of
    another format or configs, or one whose networks hold NaN or infinite values."""
    path = Path(group_dir) / GROUP_CHECKPOINT_FILE
    payload = load_torch_file(path, "spikectl seed-group checkpoint", configs[0].train.device)
    if not isinstance(payload, dict) or payload.get("format") != GROUP_FORMAT:
        raise RunDirError(f"{path} is not a spikectl seed-group checkpoint")
    if payload.get("format_version") != GROUP_VERSION:
        raise RunDirError(
            f"{path} has seed-group checkpoint format {payload.get('format_version')}; this "
            f"spikectl reads format {GROUP_VERSION}"
        )
    checksum = payload.pop("checksum", None)
    if payload_checksum(payload) != checksum:
        raise RunDirError(f"{path} is damaged: its checksum does not match its contents")
    if [saved_config(values) for values in payload["configs"]] != configs:
        raise RunDirError(f"{path} was written for other configs than {group_dir / GROUP_FILE}")
    check_finite(payload["online"], str(path))
    check_finite(payload["target"], str(path))
    states = []
    try:
        online.load_stacked_state(payload["online"])
        target.load_stacked_state(payload["target"])
        if predictor is not None:
            predictor.load_stacked_state(payload["predictor"])
        optimizer.load_state_dict(payload["optimizer"])
        for seed, replay in zip(payload["seeds"], replays, strict=True):
            states.append(restore_state(seed, replay))
    except (RuntimeError, ValueError, KeyError, TypeError) as error:
        raise RunDirError(f"{path} does not fit this group: {first_line(error)}") from None
    return states


def group_configs(group_dir: str | os.PathLike) -> tuple[list[Experiment], list[Path]]:
    """The seeds' configs and run directories saved in a group directory."""
    group_dir = Path(group_dir)
    description = read_group(group_dir)
    try:
        configs = [Experiment.from_dict(values) for values in description["configs"]]
        run_dirs = [group_dir / relative for relative in description["run_dirs"]]
    except (KeyError, TypeError, ValueError) as error:
        raise RunDirError(
            f"{group_dir / GROUP_FILE} is not a valid seed-group file: {first_line(error)}"
        ) from None
    return configs, run_dirs
