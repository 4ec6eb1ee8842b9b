"""The paper's splits of generated networks, and writing several sets as one.

:func:`make_splits` draws a training and a test set (and optionally a validation set)
with no topology shared within or across them; :func:`save_sets` writes several sets so
that either all of them or none is written.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spikectl.contexts.context_set import ContextSet
from spikectl.contexts.generation import check_seed, check_size
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.seeds import VALIDATION_STREAM


def save_sets(sets: Mapping[str | os.PathLike, ContextSet]) -> list[Path]:
    """Write several sets as one (a training and a test set): every output is checked
    before any is written (a folder, a symbolic link, a FIFO or a device is refused,
    ValueError naming it), each set goes to a temporary file beside its output, and only
    when all are written are they renamed into place. A refusal or a failed write leaves
    none of them written. Returns the paths (``.npz`` added as :meth:`ContextSet.save`
    adds it)."""
    paths = check_set_outputs(sets)
    pending = [path.with_name(f".{path.name}.{os.getpid()}.pending.npz") for path in paths]
    try:
        for contexts, temporary in zip(sets.values(), pending, strict=True):
            contexts.save(temporary)
        for temporary, path in zip(pending, paths, strict=True):
            os.replace(temporary, path)
    finally:
        for temporary in pending:
            temporary.unlink(missing_ok=True)
    return paths


def check_set_outputs(outputs: Iterable[str | os.PathLike]) -> list[Path]:
    """The paths :func:`save_sets` writes, each checked: an existing folder, symbolic
    link, FIFO or device is refused (ValueError naming it) before any set is made."""
    paths = []
    for given in outputs:
        path = Path(given)
        paths.append(path if path.suffix == ".npz" else path.with_suffix(path.suffix + ".npz"))
    for path in paths:
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            continue
        if not stat.S_ISREG(mode):
            kind = "a symbolic link" if stat.S_ISLNK(mode) else "not a regular file"
            kind = "a folder" if stat.S_ISDIR(mode) else kind
            raise ValueError(
                f"{path} is {kind}; refusing to replace it (nothing was written: remove it, "
                "or write the sets elsewhere)"
            )
    return paths


def make_splits(
    n_train: int = 100,
    n_test: int = 100,
    n_neurons: int = 8,
    episode_length: int = 60,
    seed: int = 0,
    params: NeuronParams | None = None,
    extensions: Extensions | Mapping[str, Any] | None = None,
    n_val: int = 0,
) -> tuple[ContextSet, ...]:
    """A training and a test set (and, with ``n_val > 0``, a validation set) with no
    topology shared within or across them.

    The test set is drawn first and the training set continues the same stream, so
    for one seed the test set does not depend on ``n_train`` and smaller training
    sets are prefixes of larger ones (the paper's Figure 5 compares sizes on one
    test set). Context-level ``extensions`` are drawn with each context.

    ``n_val > 0`` returns ``(train, test, validation)``: the validation set, for
    choosing settings without looking at the test set, comes from a stream of its
    own (``VALIDATION_STREAM``), so adding it changes neither of the other two and
    it does not depend on ``n_train`` (beyond skipping, with vanishing probability,
    a topology the training set already holds).
    """
    n_train = check_size(n_train, "n_train")
    n_test = check_size(n_test, "n_test")
    seed = check_seed(seed)
    if isinstance(n_val, bool) or not isinstance(n_val, int | np.integer) or n_val < 0:
        raise ValueError(f"n_val must be a non-negative integer, got {n_val!r}")
    test, train = ContextSet.draw(
        [n_test, n_train], n_neurons, episode_length, seed, params, extensions
    )
    if not n_val:
        return train, test
    validation = make_validation_set(
        int(n_val), (train, test), n_neurons, episode_length, seed, params, extensions
    )
    return train, test, validation


def make_validation_set(
    n_val: int,
    exclude: Sequence[ContextSet],
    n_neurons: int = 8,
    episode_length: int = 60,
    seed: int = 0,
    params: NeuronParams | None = None,
    extensions: Extensions | Mapping[str, Any] | None = None,
) -> ContextSet:
    """A validation set with no topology shared with itself or with any set in ``exclude``
    (the training and test sets), from a generator stream of its own (``VALIDATION_STREAM``)."""
    n_val = check_size(n_val, "n_val")
    (validation,) = ContextSet.draw(
        [n_val], n_neurons, episode_length, seed, params, extensions,
        stream=VALIDATION_STREAM, exclude=exclude,
    )  # fmt: skip
    return validation
