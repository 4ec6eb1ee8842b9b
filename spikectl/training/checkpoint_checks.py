"""What a checkpoint may hold, checked before any of it is used.

The checksum tells a damaged file from a whole one, not a crafted (or buggy) one from
spikectl's own: a file whose checksum was recomputed over missing, extra or misshapen
entries loads. So every entry is checked against what the run would write: each seed's
part of the state (``check_runs``), the learners' state against the state the freshly
made learners have (``check_learner_state``) and, once loaded, the optimisers' moments
against their parameters (``check_optimizers``). Each failure is a RunDirError naming
the file and the entry, never a traceback from deep inside the first update.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spikectl.training.run_files import CLOCK_FIELDS, RunDirError

TOP_ENTRIES = {"format", "format_version", "spikectl_version", "configs", "stacked",
               "learners", "runs", "checksum"}  # fmt: skip
RUN_ENTRIES = {"rng", "episodes", "wall_time_s", "cpu_time_s", "eval_cpu_time_s", "metrics",
               "baselines", "contexts", "best_model"}  # fmt: skip
ROW_NEEDS = ("episode", "env_steps", "train_return", "test_return")
BASELINES = ("do_nothing", "random")


def _damaged(path: Path, what: str) -> RunDirError:
    return RunDirError(f"{path} is damaged: {what}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_entries(path: Path, payload: dict[str, Any]) -> None:
    """Refuse entries a format-3 checkpoint never holds, at its top and in its runs."""
    for where, entries, known in [("", payload, TOP_ENTRIES)] + [
        (f"run {k}: ", run, RUN_ENTRIES) for k, run in enumerate(payload["runs"])
    ]:
        unknown = sorted(str(key) for key in entries if key not in known)
        if unknown:
            raise _damaged(path, f"{where}unexpected entry {unknown[0]!r}")


def check_runs(path: Path, runs: list[dict[str, Any]], total_episodes: list[int]) -> None:
    """Each seed's part of the state: counts and clocks in range, the seeds in lockstep,
    metrics rows of numbers in episode order, the baselines of both sets."""
    episodes = {run["episodes"] for run in runs}
    if len(episodes) > 1:
        raise _damaged(path, f"its seeds are at different episodes ({sorted(episodes)})")
    for k, (run, total) in enumerate(zip(runs, total_episodes, strict=True)):
        seed = f"run {k}: " if len(runs) > 1 else ""
        if not 0 <= run["episodes"] <= total:
            raise _damaged(path, f"{seed}episode {run['episodes']} is outside 0..{total}")
        for clock in CLOCK_FIELDS:
            value = run.get(clock, 0.0)
            if clock == "eval_cpu_time_s" and _is_number(value) and math.isnan(value):
                continue  # a run resumed from a checkpoint before this clock never has one
            if not _is_number(value) or not math.isfinite(value) or value < 0:
                raise _damaged(path, f"{seed}{clock} is not a time in seconds: {value!r}")
        _check_metrics(path, seed, run["metrics"], run["episodes"])
        baselines = run["baselines"]
        if not all(
            isinstance(baselines.get(name), dict)
            and all(_is_number(baselines[name].get(split)) for split in ("train", "test"))
            for name in BASELINES
        ):
            raise _damaged(path, f"{seed}its baselines are not do_nothing's and random's "
                                 "train and test returns")  # fmt: skip
        contexts = run.get("contexts", {})
        if not isinstance(contexts, dict) or not all(
            isinstance(v, str) for v in contexts.values()
        ):  # fmt: skip
            raise _damaged(path, f"{seed}its 'contexts' entry is not checksums by set")


def _check_metrics(path: Path, seed: str, rows: list, episodes: int) -> None:
    if not rows:  # the evaluation at episode 0 comes before the first checkpoint
        raise _damaged(path, f"{seed}it has no metrics rows")
    last = -1
    for row in rows:
        if not isinstance(row, dict) or not all(
            isinstance(key, str) and _is_number(value) for key, value in row.items()
        ):
            raise _damaged(path, f"{seed}a metrics row is not a table of numbers: {row!r:.80}")
        missing = [key for key in ROW_NEEDS if key not in row]
        if missing:
            raise _damaged(path, f"{seed}a metrics row has no {missing[0]!r}")
        if not last <= row["episode"] <= episodes:
            raise _damaged(path, f"{seed}its metrics rows are not in episode order up to "
                                 f"{episodes} (episode {row['episode']})")  # fmt: skip
        last = row["episode"]


def check_learner_state(path: Path, saved: Any, fresh: Any, where: str = "learners") -> None:
    """``saved`` (the checkpoint's learner state) against ``fresh`` (the state the run's
    freshly made learners hold): no entry the learners do not have, tensors of the same
    dtype and trailing shape (rows of a replay buffer vary), numbers where numbers are,
    finite and not negative where the fresh state's are not. An empty table in the fresh
    state (an optimiser's moments before its first step) takes anything here; the moments
    are checked once loaded (``check_optimizers``). Missing entries are left to the
    learners' ``load_state_dict``, which names them."""
    if isinstance(fresh, dict):
        if not isinstance(saved, dict):
            raise _damaged(path, f"{where} is not a table")
        if fresh:
            for key, value in saved.items():
                if key not in fresh:
                    raise _damaged(path, f"{where} has an unexpected entry {key!r}")
                check_learner_state(path, value, fresh[key], f"{where}.{key}")
    elif isinstance(fresh, (list, tuple)):
        if not isinstance(saved, (list, tuple)):
            raise _damaged(path, f"{where} is not a list")
        if len(saved) == len(fresh):
            for index, (value, template) in enumerate(zip(saved, fresh, strict=True)):
                check_learner_state(path, value, template, f"{where}[{index}]")
    elif torch.is_tensor(fresh):
        if not torch.is_tensor(saved):
            raise _damaged(path, f"{where} is not a tensor")
        if saved.dtype != fresh.dtype or (saved.dim() >= 2) != (fresh.dim() >= 2) or (
            saved.dim() >= 2 and saved.shape[1:] != fresh.shape[1:]
        ):  # fmt: skip
            raise _damaged(
                path, f"{where} is a {saved.dtype} tensor of shape {tuple(saved.shape)}, the "
                f"run's is {fresh.dtype} of shape {('N', *fresh.shape[1:])}"
            )  # fmt: skip
    elif _is_number(fresh):
        if not _is_number(saved) or not math.isfinite(saved) or (fresh >= 0 > saved):
            raise _damaged(path, f"{where} is {saved!r}, not a number in range")


def check_optimizers(path: Path, learners: Any) -> None:
    """Once loaded, every optimiser's per-parameter moments have their parameter's shape
    (else the first update fails deep inside torch)."""
    for optimizer in _optimizers(learners):
        for group in optimizer.param_groups:
            for parameter in group["params"]:
                for name, value in optimizer.state.get(parameter, {}).items():
                    if torch.is_tensor(value) and value.dim() and value.shape != parameter.shape:
                        raise _damaged(
                            path, f"an optimiser's {name!r} has shape {tuple(value.shape)}, "
                            f"its parameter {tuple(parameter.shape)}"
                        )  # fmt: skip


def _optimizers(root: Any, depth: int = 4) -> list[torch.optim.Optimizer]:
    """The optimisers held by the learners (looked up through their attributes, so any
    learner's are found)."""
    found, seen = [], set()

    def walk(value: Any, depth: int) -> None:
        if depth < 0 or id(value) in seen:
            return
        seen.add(id(value))
        if isinstance(value, torch.optim.Optimizer):
            found.append(value)
        elif isinstance(value, (torch.nn.Module, torch.Tensor, np.ndarray, str, bytes)):
            return
        elif isinstance(value, dict):
            for item in value.values():
                walk(item, depth - 1)
        elif isinstance(value, (list, tuple)):
            for item in value:
                walk(item, depth - 1)
        elif hasattr(value, "__dict__"):
            for item in vars(value).values():
                walk(item, depth - 1)

    walk(root, depth)
    return found
