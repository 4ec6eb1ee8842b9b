"""best_model.pt across a resume: the checkpoint holds the best network, so the file the
run's records name is never lost.

A run keeps the weights of its best evaluation on validation in memory and in every
checkpoint (``RunState.best_model``). On resume the file in the run directory is compared
with them: the same network stays; a file the killed run wrote after its checkpoint is
replaced (the resumed run writes it again when it gets there, bit for bit); anything else
(a damaged, crafted or foreign file) is moved aside, never deleted, with a warning naming
both files; then the checkpoint's network is written as best_model.pt. Checkpoints of
spikectl before they held the network (``LEGACY``) cannot restore it: a file there that
is not a model taken before the checkpoint is moved aside just the same.
"""

from __future__ import annotations

import copy
import warnings
from collections import OrderedDict
from pathlib import Path
from typing import Any

import torch

from spikectl.training.run_files import BEST_MODEL_FILE, RunDirError
from spikectl.training.torch_files import (
    load_model_weights,
    model_episode,
    payload_checksum,
    save_weights,
)

LEGACY = "not kept"
"""``RunState.best_model`` of a checkpoint written before checkpoints held it."""


def kept_network(network: torch.nn.Module, episode: int) -> dict[str, Any]:
    """What a checkpoint keeps of the best network: its episode and a copy of its weights
    (the network goes on training)."""
    weights = {name: value.detach().clone() for name, value in network.state_dict().items()}
    return {"episode": int(episode), "weights": weights}


def check_kept(best: Any, path: Path) -> None:
    """Refuse a checkpoint entry for the best network that is not None, LEGACY or
    ``{"episode": int, "weights": {name: tensor}}``."""
    if best is None or best == LEGACY:
        return
    if (
        not isinstance(best, dict)
        or set(best) != {"episode", "weights"}
        or not isinstance(best["episode"], int)
        or not isinstance(best["weights"], dict)
        or not all(torch.is_tensor(value) for value in best["weights"].values())
    ):
        raise RunDirError(f"{path} is damaged: its 'best_model' entry is not a network")


def restore_best_model(run_dir: Path, best: Any, episodes: int, network: torch.nn.Module) -> None:
    """Make ``run_dir/best_model.pt`` the best network of the checkpoint being resumed
    (``best``: ``kept_network``'s dict, None when the run has none yet, or LEGACY) at
    ``episodes``; ``network`` is the run's acting network, the template of the file."""
    path = run_dir / BEST_MODEL_FILE
    problem = _mismatch(path, best, episodes)
    if problem is not None:
        aside = _set_aside(path)
        remedy = (
            "the checkpoint cannot restore it (written by an older spikectl)"
            if best == LEGACY
            else "best_model.pt is written again from the checkpoint"
        )
        warnings.warn(
            f"{path} is not the best network of the checkpoint resumed ({problem}): moved "
            f"aside to {aside.name}; {remedy}",
            RuntimeWarning,
            stacklevel=2,
        )
    if best is not None and best != LEGACY and not path.exists():
        save_weights(path, fitting_weights(best, network), best["episode"])


def fitting_weights(best: dict[str, Any], network: torch.nn.Module) -> OrderedDict:
    """The kept best network as a state dict in ``network``'s layout (its key order and
    ``_metadata``); a ValueError if it does not fit ``network`` or is not finite."""
    template = network.state_dict()
    try:
        copy.deepcopy(network).load_state_dict(best["weights"])
    except (RuntimeError, KeyError, TypeError) as error:
        detail = " ".join(str(error).split())  # torch's first line names no tensor
        raise ValueError(f"its best network does not fit: {detail[:200]}") from None
    if not all(torch.isfinite(value).all() for value in best["weights"].values()
               if value.is_floating_point()):  # fmt: skip
        raise ValueError("its best network holds NaN or infinite values")
    weights = OrderedDict((name, best["weights"][name]) for name in template)
    weights._metadata = copy.deepcopy(template._metadata)
    return weights


def _mismatch(path: Path, best: Any, episodes: int) -> str | None:
    """Why the file at ``path`` is not the checkpoint's best network and must be moved
    aside; None when it is, when there is no file, or when it is a network the killed
    run took after its checkpoint (it is removed: the resumed run writes it again)."""
    if not path.exists() and not path.is_symlink():
        return None
    try:
        weights = load_model_weights(path)
        taken_at = model_episode(path)
    except RunDirError as error:
        return str(error).removeprefix(str(path)).strip(" :").removeprefix("is ")
    if taken_at is not None and taken_at > episodes:
        path.unlink()
        return None
    if best == LEGACY:
        return None if taken_at is not None else "it records no episode"
    if best is None:
        return f"a network of episode {taken_at}; the run has no best network yet"
    if taken_at != best["episode"]:
        return f"taken at episode {taken_at}; the run's best is episode {best['episode']}"
    if payload_checksum(dict(weights)) != payload_checksum(dict(best["weights"])):
        return f"other weights than the run's best network of episode {taken_at}"
    return None


def _set_aside(path: Path) -> Path:
    """Rename ``path`` to a free name beside it (best_model.set-aside[-N].pt)."""
    for number in range(1, 10_000):
        suffix = "" if number == 1 else f"-{number}"
        aside = path.with_name(f"{path.stem}.set-aside{suffix}{path.suffix}")
        if not aside.exists() and not aside.is_symlink():
            path.rename(aside)
            return aside
    raise RunDirError(f"{path.parent} holds too many set-aside copies of {path.name}")
