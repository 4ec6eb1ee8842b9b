"""What a caller hands ``reset`` and ``step``, checked the same way at every entry point.

Seeds: :func:`check_seed` (one environment) and :func:`seed_list` (a batch) are the one
rule of the single, batched and flat environments and the Stable-Baselines3 adapter; a
seed outside it is a :class:`SeedError` naming ``seed`` and what was given, never a
float silently truncated or a dict's keys taken for seeds. Actions: the batched
environments report bad actions with :func:`bad_actions_message`, whose length does not
grow with the number of environments (one bad action among 200 000 is one short line).
"""

from __future__ import annotations

import reprlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from spikectl.contexts.generation import is_int

SEED_RULE = "None or an integer >= 0 (Python or NumPy)"


class SeedError(ValueError, TypeError):
    """A seed given to ``reset`` that is not :data:`SEED_RULE` (for a batch: that, or a
    list, tuple or array of one per environment). A ValueError and a TypeError, so code
    catching either of Gymnasium's seed errors catches it."""


_SHORT = reprlib.Repr()
_SHORT.maxstring, _SHORT.maxother, _SHORT.maxlist, _SHORT.maxtuple = 40, 60, 6, 6
_SHORT.maxdict = 4


def short_repr(value: Any) -> str:
    """``repr(value)`` cut to a few dozen characters (a huge list or array stays short)."""
    if isinstance(value, np.ndarray) and value.size > 6:
        return f"array of shape {value.shape} and dtype {value.dtype}"
    return _SHORT.repr(value)


def _is_seed(value: Any) -> bool:
    return is_int(value) and value >= 0


def check_seed(seed: Any) -> int | None:
    """The seed of one environment as a Python int (None stays None), or SeedError."""
    if seed is None:
        return None
    if not _is_seed(seed):
        raise SeedError(f"seed must be {SEED_RULE}, got {_described(seed)}")
    return int(seed)


def seed_list(seed: Any, num_envs: int) -> list[int | None]:
    """One seed per environment, as Gymnasium's vector environments take them: None (all
    unseeded), one integer ``s`` (environment i gets ``s + i``) or a list, tuple or 1-d
    array of ``num_envs`` seeds (each an integer >= 0 or None); anything else SeedError."""
    if seed is None:
        return [None] * num_envs
    if _is_seed(seed):
        return [int(seed) + i for i in range(num_envs)]
    rule = (f"{SEED_RULE}, or a list of num_envs={num_envs} of them (one per environment, "
            "None for unseeded)")  # fmt: skip
    if isinstance(seed, np.ndarray) and seed.ndim == 1 and seed.dtype.kind in "iuO":
        seed = list(seed)
    if not isinstance(seed, (list, tuple)):
        raise SeedError(f"seed must be {rule}, got {_described(seed)}")
    if len(seed) != num_envs:
        raise SeedError(f"seed must be {rule}, got a {type(seed).__name__} of {len(seed)}")
    for i, value in enumerate(seed):
        if value is not None and not _is_seed(value):
            raise SeedError(f"seed[{i}] must be {SEED_RULE}, got {_described(value)}")
    return [None if value is None else int(value) for value in seed]


def _described(value: Any) -> str:
    return short_repr(value) if is_int(value) else f"{short_repr(value)} ({type(value).__name__})"


MAX_LISTED = 5
"""The most bad actions a message lists (it gives the count of all)."""
TARGET_RULE = "an action that stimulates the target neuron is not legal"


def bad_actions_message(actions: np.ndarray, bad: np.ndarray, problem: str, rule: str) -> str:
    """One line for the bad entries (the bool mask ``bad``) of a batch of ``actions``:
    their count, the first :data:`MAX_LISTED` environments and values, and ``rule`` (what
    an action may be). Its length does not depend on the batch size."""
    where = np.flatnonzero(bad)
    listed = ", ".join(f"env {i}: action {actions[i]}" for i in where[:MAX_LISTED])
    if where.size > MAX_LISTED:
        listed += f", ... {where.size - MAX_LISTED:,} more"
    return f"{where.size:,} of {bad.size:,} actions {problem} ({listed}): {rule}"


def bad_shape_message(actions: Any, num_envs: int, rule: str) -> str:
    """One line for a batch of actions of the wrong shape or type (its values unlisted)."""
    array = np.asarray(actions)
    return (f"actions must be {rule} of shape ({num_envs},), got {array.dtype} "
            f"{array.shape}")  # fmt: skip


def context_choices(choice: Any, envs: np.ndarray, num_envs: int) -> list[Any]:
    """A batch's ``context`` reset option for each env in ``envs``: None (draw), an index
    or a Context for all, or one of a sequence of ``num_envs`` of them."""
    from spikectl.contexts import Context

    if choice is None or isinstance(choice, (Context, int, np.integer)):
        return [choice] * envs.size
    if isinstance(choice, (str, bytes)) or not isinstance(choice, (Sequence, np.ndarray)):
        raise TypeError(
            f"the context option must be an index, a Context, or a sequence of "
            f"num_envs={num_envs} of them; got {type(choice).__name__}"
        )
    if len(choice) != num_envs:
        raise ValueError(
            f"a sequence of contexts must have num_envs={num_envs} entries, got {len(choice)}"
        )
    return [choice[i] for i in envs]


def reset_mask(mask: Any, num_envs: int) -> np.ndarray:
    """A batch's ``reset_mask`` reset option: all envs for None, else a bool array
    [num_envs] marking at least one."""
    if mask is None:
        return np.ones(num_envs, dtype=bool)
    if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (num_envs,):
        raise ValueError(f"options['reset_mask'] must be a bool array of shape ({num_envs},)")
    if not mask.any():
        raise ValueError("options['reset_mask'] must mark at least one sub-environment")
    return mask


def batch_reset_options(options: Any, num_envs: int) -> tuple[np.ndarray, Any]:
    """A batch's reset ``options`` (None or a dict of ``reset_mask`` and ``context``) as
    (the bool [num_envs] mask of the envs to reset, the context option unchecked)."""
    if options is not None and not isinstance(options, Mapping):
        raise TypeError(
            "options must be a dict such as {'context': [0, 1]} or None, "
            f"got {type(options).__name__}"
        )
    options = dict(options or {})
    which = reset_mask(options.pop("reset_mask", None), num_envs)
    choice = options.pop("context", None)
    if options:
        raise ValueError(
            f"unknown reset option(s) {sorted(options)}; the options are 'context' and 'reset_mask'"
        )
    return which, choice


__all__ = [
    "MAX_LISTED", "SEED_RULE", "TARGET_RULE", "SeedError", "bad_actions_message",
    "bad_shape_message", "batch_reset_options", "check_seed", "context_choices",
    "reset_mask", "seed_list", "short_repr",
]  # fmt: skip
