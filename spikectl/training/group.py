"""Seed groups: K runs of one configuration trained in one process.

``spikectl train --seeds 0 1 2`` (or ``sweep --group-seeds``) trains the seeds as one
group: the training loop (``spikectl.training.run``) plays a round of all seeds at once
and lets each seed's learner learn. Looped (the default), the seeds share nothing but the
process and the vector environment's blocks: each seed trains bit-identically to the same
seed alone. Stacked (``--stacked``), the learners compute all K seeds at once (a GPU's
way; equal up to rounding). Each seed has its own run directory (RUN_DIR/seed=S) with the
files of a single run. The group directory holds ``group.json`` (the seeds' configs, run
directories and whether stacked) and ``checkpoint.pt`` (every seed's state, one file, so
the seeds stay in lockstep). The configs may differ in seed and training-set size
(Figure 5's sizes x seeds form one group).

Groups written by spikectl before the training loop took learners as plug-ins hold
``group_checkpoint.pt``; their seeds' finished runs load as ever, an unfinished group
cannot be resumed (one clear error).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from spikectl.files import make_dirs, read_json_file, write_json
from spikectl.training.config import Experiment
from spikectl.training.run_files import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    LOCK_FILE,
    MODEL_FILE,
    RunDirError,
    prepare_run_dir,
    read_config,
    remove_temporaries,
)
from spikectl.training.torch_files import first_line

GROUP_FILE = "group.json"
STACKED_GROUP_CHECKPOINT = "group_checkpoint.pt"
"""The one checkpoint of a stacked group (spikectl before the plug-in loop)."""


def group_key(config: Experiment) -> Experiment:
    """What the members of one seed group share: the config up to its seed and its
    training-set size."""
    shared = config.with_seed(0)
    return dataclasses.replace(shared, env=dataclasses.replace(shared.env, n_train=1))


def seed_dirs(run_dir: str | Path, seeds: list[int]) -> list[Path]:
    """The seeds' run directories of a group trained with ``spikectl train --seeds``."""
    return [Path(run_dir) / f"seed={seed}" for seed in seeds]


def check_group(configs: list[Experiment], run_dirs: list[Path]) -> None:
    """Refuse a group that is empty, has distinct settings, repeated seeds or shared
    run directories."""
    if not configs:
        raise ValueError("a seed group needs at least one config")
    if len(configs) != len(run_dirs):
        raise ValueError(f"{len(configs)} configs but {len(run_dirs)} run directories")
    first = group_key(configs[0])
    if any(group_key(config) != first for config in configs[1:]):
        raise ValueError(
            "the configs of a seed group may differ only in seed and n_train "
            "(the size of the training set)"
        )
    members = [(config.train.seed, config.env.n_train) for config in configs]
    if len(set(members)) != len(members):
        raise ValueError(
            f"the seeds of a group must be distinct (per training-set size), got "
            f"{[seed for seed, _ in members]}"
        )
    if len({Path(d).resolve() for d in run_dirs}) != len(run_dirs):
        raise ValueError("the seeds of a group need distinct run directories")


def group_description(
    configs: list[Experiment], run_dirs: list[Path], group_dir: Path, stacked: bool = False
) -> dict:
    """What group.json holds: the seeds' configs and run directories (relative to the
    group directory when inside it) and whether they train stacked."""
    return {
        "format": "spikectl.group",
        "configs": [config.to_dict() for config in configs],
        "run_dirs": [os.path.relpath(Path(d).resolve(), group_dir.resolve()) for d in run_dirs],
        "stacked": bool(stacked),
    }


def read_group(group_dir: str | os.PathLike) -> dict:
    """The description a group directory holds (group.json)."""
    path = Path(group_dir) / GROUP_FILE
    if not path.exists():
        raise RunDirError(f"{group_dir} holds no seed group (no {GROUP_FILE})")
    try:
        description = read_json_file(path)
    except (OSError, ValueError) as error:
        raise RunDirError(f"{path} is not a valid seed-group file: {first_line(error)}") from None
    if not isinstance(description, dict):
        raise RunDirError(f"{path} is not a valid seed-group file: not a JSON object")
    return description


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


def group_is_stacked(group_dir: str | os.PathLike) -> bool:
    """Whether the group in ``group_dir`` trains stacked (groups before the flag: no)."""
    stacked = read_group(group_dir).get("stacked", False)
    if not isinstance(stacked, bool):
        raise RunDirError(f"{Path(group_dir) / GROUP_FILE} is damaged: 'stacked' is not a bool")
    return stacked


def prepare_group(
    configs: list[Experiment],
    run_dirs: list[Path],
    group_dir: Path,
    resume: bool,
    stacked: bool = False,
) -> bool:
    """Create the group and its seeds' run directories, or check that ``group_dir`` holds
    this group to resume. Returns whether there is a group checkpoint to resume from; a
    group that stopped before its first checkpoint starts again from step 0."""
    if (group_dir / STACKED_GROUP_CHECKPOINT).exists():
        raise RunDirError(
            f"{group_dir} holds a seed group of an earlier spikectl ({STACKED_GROUP_CHECKPOINT}); "
            "this version cannot resume it: finish it with the version that started it, or "
            "start the group again in another --run-dir (its finished seeds' model.pt load)"
        )
    has_file = (group_dir / GROUP_FILE).exists()
    has_checkpoint = (group_dir / CHECKPOINT_FILE).exists()
    if has_file:
        saved, saved_dirs = group_configs(group_dir)
        if (
            saved != configs
            or [d.resolve() for d in saved_dirs] != [Path(d).resolve() for d in run_dirs]
            or group_is_stacked(group_dir) != stacked
        ):
            raise RunDirError(
                f"{group_dir} holds another seed group (its {GROUP_FILE} has other configs, "
                "seeds or --stacked): choose another --run-dir"
            )
    elif resume:
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
        if (run_dir / CHECKPOINT_FILE).exists() or (run_dir / MODEL_FILE).exists():
            raise RunDirError(f"{run_dir} already holds a run: it cannot join a seed group")
        # A seed's directory from a group that never checkpointed starts again too.
        prepare_run_dir(config, run_dir, resume=(run_dir / CONFIG_FILE).exists())
    make_dirs(group_dir)
    write_json(group_dir / GROUP_FILE, group_description(configs, run_dirs, group_dir, stacked))
    return False
