"""Grids of independent, resumable training trials under one sweep directory.

A sweep is a base ``Experiment`` and a grid: every combination of the listed values
of some config fields (architecture, seed, training-set size, any other field) is one
trial, trained in ``SWEEP_DIR/trials/NAME``. Fields are named by their dotted path in
the tree (``"env.n_train"``, ``"agent.arch"``, ``"env.extensions.observation_noise_mV"``)
or, as in sweep files written before the tree, by their flat name (``"n_train"``,
``"arch"``, ``"seed"``); overrides may also be nested objects (``{"env": {"n_train":
20}}``). Running a sweep again skips finished
trials (``model.pt`` present) and resumes interrupted ones exactly (the trainer's
checkpoints), so a sweep can be stopped and restarted at any moment.

Trials run in a local process pool (one worker per core by default); each trial uses
one Torch thread so that workers do not fight over cores and so that a trial's result
does not depend on how many ran beside it. With ``group_seeds`` the trials that differ
only in seed and training-set size run as one seed group per process
(``spikectl.training.group``), each still in its own trial directory and bit-identical
to the trial trained alone; the group's description lives in ``SWEEP_DIR/groups/``.
The same tasks can run as Ray tasks or as Slurm jobs through submitit
(:mod:`spikectl.experiments.backends`), each trial ending the same.
"""

from __future__ import annotations

import itertools
import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spikectl.agents import ARCHITECTURES
from spikectl.experiments.backends import Backend
from spikectl.experiments.slurm import JobLostError
from spikectl.files import FileWriteError, make_dirs, read_json_file, write_json
from spikectl.training.config import Experiment, field_value
from spikectl.training.group import GROUP_FILE, group_key
from spikectl.training.presets import PRESETS
from spikectl.training.run_files import CHECKPOINT_FILE, CONFIG_FILE, MODEL_FILE, RunDirError
from spikectl.training.torch_files import load_model_weights

SWEEP_FILE = "sweep.json"
TRIALS_DIR = "trials"
GROUPS_DIR = "groups"

PAPER_SWEEPS: dict[str, dict[str, Any]] = {
    "fig4": {"base": "paper", "grid": {"arch": list(ARCHITECTURES),
                                       "seed": list(range(10))}},
    "fig5": {"base": "paper", "grid": {"arch": ["tdrqn"], "n_train": [10, 20, 40, 100],
                                       "seed": list(range(10))}},
}  # fmt: skip
"""The paper's two experiments: Figure 4 (architectures) and Figure 5 (training-set size)."""
TRIAL_ERRORS = (ValueError, FileNotFoundError, FileWriteError, RunDirError, JobLostError)
"""Failures of a trial that are about its inputs or files, or a Slurm job lost (reported
in one line each); anything else is a bug and keeps its traceback."""


class SweepError(RuntimeError):
    """Some trials of a sweep failed; the message names each and its error."""


@dataclass(frozen=True)
class Sweep:
    """A base config and a grid of field values; each combination is one trial."""

    base: Experiment
    grid: Mapping[str, Sequence[Any]]

    def __post_init__(self) -> None:
        base = self.base.to_dict()
        for name in self.grid:
            try:
                value = field_value(base, name)
            except ValueError:
                raise ValueError(f"sweep grid names an unknown config field {name!r}") from None
            if isinstance(value, dict):
                raise ValueError(f"sweep grid field {name!r} is a group of fields: name one")
        for name, values in self.grid.items():
            if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
                raise ValueError(f"sweep grid field {name!r} needs a non-empty list of values")

    def trials(self) -> list[tuple[str, Experiment]]:
        """(name, config) of every trial, in grid order; names are unique and stable."""
        names = list(self.grid)
        trials = []
        for values in itertools.product(*(self.grid[name] for name in names)):
            changes = dict(zip(names, values, strict=True))
            config = self.base.with_changes({**changes, "train.progress": False})
            # A value's "/" (an environment id) would nest directories: "_" instead.
            label = (
                "-".join(
                    f"{name}={str(value).replace('/', '_')}" for name, value in changes.items()
                )
                or "base"
            )
            trials.append((label, config))
        return trials

    def to_dict(self) -> dict[str, Any]:
        return {"base": self.base.to_dict(), "grid": {k: list(v) for k, v in self.grid.items()}}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Sweep:
        """From a sweep file: ``base`` is a preset name or a config dict, plus optional
        ``overrides`` (fields of the base changed for every trial) and the ``grid``."""
        if not isinstance(values, Mapping):
            raise ValueError(
                f"a sweep description is a JSON object with base, overrides and grid, "
                f"got {type(values).__name__}"
            )
        base = values.get("base", "quick")
        if isinstance(base, str):
            if base not in PRESETS:
                raise ValueError(f"unknown base preset {base!r}; choose one of {sorted(PRESETS)}")
            base_config = PRESETS[base]
        else:
            base_config = Experiment.from_dict(base)
        overrides = values.get("overrides", {})
        grid = values.get("grid", {})
        for key, value in (("overrides", overrides), ("grid", grid)):
            if not isinstance(value, Mapping):
                raise ValueError(f"the sweep's {key} must be a JSON object, got {value!r}")
        if overrides:
            # Nested overrides (sizes, params, ...) change single fields, not all of them.
            base_config = base_config.with_changes(overrides)
        unknown = sorted(set(values) - {"base", "overrides", "grid"})
        if unknown:
            raise ValueError(f"unknown sweep file key(s) {unknown}: use base, overrides, grid")
        return cls(base=base_config, grid=dict(grid))


def load_sweep_file(path: str | os.PathLike) -> Sweep:
    """Read a sweep description from a JSON file."""
    path = Path(path)
    return Sweep.from_dict(_read_json(path, "sweep file"))


def _read_json(path: Path, what: str) -> Any:
    try:
        return read_json_file(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} not found: {path}") from None
    except IsADirectoryError:
        raise ValueError(f"{path} is a folder, not a {what}") from None
    except OSError as error:
        raise ValueError(f"cannot read {path}: {error.strerror}") from error
    except ValueError as error:  # bad JSON or text, too large, nested too deeply
        raise ValueError(f"{path} is not valid JSON: {error}") from error


def _saved_sweep(path: Path) -> dict[str, Any]:
    """A saved sweep.json in today's form (one written before the tree has a flat base)."""
    try:
        return json.loads(
            json.dumps(Sweep.from_dict(_read_json(path, "sweep description")).to_dict())
        )
    except (ValueError, TypeError) as error:
        raise ValueError(f"{path} is not a valid sweep description: {error}") from None


def trial_status(run_dir: Path) -> str:
    """'done' (final weights written), 'interrupted' (has a checkpoint) or 'new'.

    The final weights of a done trial are verified (checksum), so a damaged model.pt is
    a RunDirError, never counted as done.
    """
    if (run_dir / MODEL_FILE).exists():
        load_model_weights(run_dir / MODEL_FILE)
        return "done"
    if (run_dir / CHECKPOINT_FILE).exists():
        return "interrupted"
    return "new"


def run_trial(config: Experiment, run_dir: str | os.PathLike) -> dict[str, Any]:
    """Train one trial to the end: skip it if done, resume it if interrupted."""
    return run_trials([config], [run_dir])[0]


def run_trials(
    configs: list[Experiment],
    run_dirs: list[str | os.PathLike],
    group_dir: str | os.PathLike | None = None,
    stacked: bool = False,
) -> list[dict[str, Any]]:
    """Train trials to the end in this process, as a seed group in ``group_dir`` when
    given (trials that differ only in seed and n_train; each keeps its own run
    directory; ``stacked``: one stacked computation): done trials are skipped,
    interrupted ones resumed."""
    import torch

    from spikectl.training.run import train_runs

    run_dirs = [Path(d) for d in run_dirs]
    statuses = [trial_status(run_dir) for run_dir in run_dirs]
    if group_dir is None and statuses == ["done"]:
        return [{"run_dir": str(run_dirs[0]), "status": "skipped (done)"}]
    # A trial stopped before its first checkpoint starts again from step 0 (the trainer
    # does that under the run directory's lock, so two sweeps never clobber a trial).
    torch.set_num_threads(configs[0].train.torch_threads or 1)
    if group_dir is None:
        resume = statuses == ["interrupted"]
        label = "resumed" if resume else "trained"
    else:
        resume = (Path(group_dir) / GROUP_FILE).exists()
        label = f"{'resumed' if resume else 'trained'} in a group of {len(configs)}"
    metrics = train_runs(configs, run_dirs, group_dir, resume=resume, stacked=stacked)
    return [
        {
            "run_dir": str(run_dir),
            "status": label,
            "train_return": rows[-1]["train_return"],
            "test_return": rows[-1]["test_return"],
        }
        for run_dir, rows in zip(run_dirs, metrics, strict=True)
    ]


def seed_group_tasks(
    jobs: list[tuple[Experiment, Path]], sweep_dir: Path, stacked: bool = False
) -> list[tuple]:
    """(function, arguments, run_dir) tasks: trials that differ only in seed and
    training-set size (``group.group_key``) become one ``run_trials`` group in
    ``SWEEP_DIR/groups/NAME``; trials already done or interrupted as single runs stay
    single ``run_trial`` tasks."""
    groups: dict[Experiment, list[tuple[Experiment, Path]]] = {}
    tasks = []
    for config, run_dir in jobs:
        if trial_status(run_dir) != "new":
            tasks.append((run_trial, (config, run_dir), run_dir))
        else:
            groups.setdefault(group_key(config), []).append((config, run_dir))
    for members in groups.values():
        if len(members) == 1:
            tasks.append((run_trial, members[0], members[0][1]))
            continue
        varying = ("seed=",) if len({c.env.n_train for c, _ in members}) == 1 else (
            "seed=", "n_train=")  # fmt: skip
        name = (
            "-".join(part for part in members[0][1].name.split("-")
                     if not part.startswith(varying))
            or "base"
        )  # fmt: skip
        group_dir = sweep_dir / GROUPS_DIR / name
        configs = [config for config, _ in members]
        run_dirs = [run_dir for _, run_dir in members]
        tasks.append((run_trials, (configs, run_dirs, group_dir, stacked), group_dir))
    return tasks


def run_sweep(
    sweep: Sweep,
    sweep_dir: str | os.PathLike,
    backend: Backend | None = None,
    *,
    group_seeds: bool = False,
    stacked: bool = False,
    echo: Callable[[str], Any] = print,
) -> list[dict[str, Any]]:
    """Run every trial of ``sweep`` under ``sweep_dir`` on ``backend`` (default: a local
    process pool of one worker per core, :class:`~spikectl.experiments.backends.Backend`).
    Each trial's result is the same whichever backend ran it. ``group_seeds``: trials
    that differ only in seed and n_train train as one seed group per process
    (``run_trials``), each trial exactly as alone; with ``stacked`` as one stacked
    computation (for GPUs; equal up to rounding). ``echo`` takes each progress line.
    """
    if stacked and not group_seeds:
        raise ValueError("stacked: stacking computes seed groups; ask for group_seeds too")
    backend = Backend() if backend is None else backend
    if not isinstance(backend, Backend):
        raise TypeError(f"backend must be a Backend, got {type(backend).__name__}")
    backend.check()
    sweep_dir = Path(sweep_dir).resolve()
    if sweep_dir.exists() and not sweep_dir.is_dir():
        raise ValueError(f"{sweep_dir} is a file, not a sweep directory")
    saved = sweep_dir / SWEEP_FILE
    description = json.loads(json.dumps(sweep.to_dict()))  # tuples as JSON reads them back
    if saved.exists() and _saved_sweep(saved) != description:
        raise ValueError(
            f"{sweep_dir} holds another sweep ({SWEEP_FILE} differs): choose another directory"
        )
    make_dirs(sweep_dir)
    write_json(saved, sweep.to_dict())
    trials = sweep.trials()
    where = backend.describe(sweep_dir, len(trials))
    echo(f"{len(trials)} trials in {sweep_dir / TRIALS_DIR}, {where}")
    results = []
    # torch_threads=1: one core per trial, and results independent of the pool size.
    jobs = [
        (config.with_changes({"train.torch_threads": 1}), sweep_dir / TRIALS_DIR / name)
        for name, config in trials
    ]
    if group_seeds:
        tasks = seed_group_tasks(jobs, sweep_dir, stacked)
    else:
        tasks = [(run_trial, (config, run_dir), run_dir) for config, run_dir in jobs]
    failures: list[tuple[str, BaseException]] = []
    outcomes = backend.run(tasks, sweep_dir, len(trials), TRIAL_ERRORS, echo)
    for outcome in outcomes:
        if isinstance(outcome, BaseException):
            name = Path(outcome.run_dir).name
            failures.append((name, outcome))
            echo(f"{name}: failed: {' '.join(str(outcome).split())}")
            continue
        for result in outcome if isinstance(outcome, list) else [outcome]:
            results.append(result)
            scores = (
                f": train {result['train_return']:.3f}, test {result['test_return']:.3f}"
                if "test_return" in result
                else ""
            )
            echo(f"{Path(result['run_dir']).name}: {result['status']}{scores}")
    bugs = [error for _, error in failures if not isinstance(error, TRIAL_ERRORS)]
    if bugs:
        raise bugs[0]
    if failures:
        name, error = failures[0]
        what = "task(s) (trials or seed groups)" if group_seeds else "trial(s)"
        raise SweepError(
            f"{len(failures)} of {len(tasks)} {what} failed (first: {name}: "
            f"{' '.join(str(error).split())}); the others finished: fix the cause and run "
            "the same command again"
        )
    return sorted(results, key=lambda result: result["run_dir"])


def trial_dirs(sweep_dir: str | os.PathLike) -> list[Path]:
    """Run directories of a sweep's trials (those with a saved config)."""
    root = Path(sweep_dir) / TRIALS_DIR
    return sorted(path for path in root.glob("*") if (path / CONFIG_FILE).exists())
