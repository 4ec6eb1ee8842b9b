"""Context sets (docs/model.md): sequences of contexts, their files and checksums.

:class:`ContextSet` holds contexts of one shape with the parameters (and context-level
extensions) they were made with, and saves to / loads from one ``.npz`` file
(``spikectl.contexts.file_format``); :mod:`spikectl.contexts.splits` draws the paper's
splits from it. Also importable from ``spikectl.contexts`` and from ``spikectl``.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator, Mapping, Sequence
from itertools import accumulate
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from spikectl.contexts.context import Context
from spikectl.contexts.file_format import ContextFileError, read_npz, write_npz
from spikectl.contexts.generation import (
    check_episode_length,
    check_n_neurons,
    check_seed,
    check_size,
    generate_distinct,
)
from spikectl.files import check_fits_in_memory
from spikectl.neuron.extensions import Extensions, Heterogeneity
from spikectl.neuron.params import NeuronParams

if TYPE_CHECKING:  # typing.Self is Python 3.11+; annotations are never evaluated here
    from typing_extensions import Self

CONTEXT_OVERHEAD_BYTES = 1024
"""About what one Context costs besides its arrays' data (objects and array headers)."""


class ContextSet(Sequence[Context]):
    """An immutable sequence of contexts of one size and episode length.

    Build one with :meth:`generate` (or :func:`make_splits`), from your own
    contexts, or with :meth:`load`. ``params`` are the model parameters the
    witnesses were made with; ``seed`` is the generation seed when there is one;
    ``extensions`` records the context-level extensions the set was generated with
    (hidden neurons, heterogeneous neurons; only those fields are kept). All
    contexts have the same n, episode length and number of hidden neurons, and
    either all or none have heterogeneous neurons.
    """

    def __init__(
        self,
        contexts: Sequence[Context],
        params: NeuronParams | None = None,
        seed: int | None = None,
        extensions: Extensions | Mapping[str, Any] | None = None,
    ) -> None:
        self._contexts = tuple(contexts)
        if not self._contexts:
            raise ValueError("a ContextSet needs at least one context")
        for index, context in enumerate(self._contexts):
            if not isinstance(context, Context):
                raise TypeError(f"item {index} is a {type(context).__name__}, not a Context")
        first = self._contexts[0]
        # The documented limits hold for sets read from files too, not only generated.
        check_n_neurons(first.n_neurons)
        check_episode_length(first.episode_length)
        for index, context in enumerate(self._contexts):
            if _shape(context) != _shape(first):
                raise ValueError(
                    f"context {index} has (n_neurons, episode_length, observed neurons, "
                    f"heterogeneous) = {_shape(context)}; context 0 has {_shape(first)}: a set "
                    "holds one shape"
                )
        self.params = NeuronParams() if params is None else params
        self.seed = seed
        self.extensions = Extensions.coerce(extensions).context_part()

    @classmethod
    def generate(
        cls,
        size: int,
        n_neurons: int = 8,
        episode_length: int = 60,
        seed: int = 0,
        params: NeuronParams | None = None,
        extensions: Extensions | Mapping[str, Any] | None = None,
    ) -> Self:
        """``size`` contexts with pairwise distinct topologies, reproducible from ``seed``.

        Sets are prefix-stable: ``generate(10, seed=s)`` is the first 10 contexts of
        ``generate(100, seed=s)``. Context-level ``extensions`` (hidden neurons,
        heterogeneous neurons) are drawn with each context.
        """
        size = check_size(size)
        return cls.draw([size], n_neurons, episode_length, seed, params, extensions)[0]

    @classmethod
    def draw(
        cls,
        sizes: Sequence[int],
        n_neurons: int,
        episode_length: int,
        seed: int,
        params: NeuronParams | None,
        extensions: Extensions | Mapping[str, Any] | None,
        *,
        stream: int | None = None,
        exclude: Sequence[ContextSet] = (),
    ) -> list[Self]:
        """Consecutive sets of ``sizes`` from one stream of distinct topologies, none of
        them in a set of ``exclude``. The stream is ``default_rng(seed)``, or with
        ``stream`` ``default_rng([seed, stream])``: every way of drawing sets goes
        through here, so a seed names the same contexts whichever asks for them."""
        seed = check_seed(seed)
        extensions = Extensions.coerce(extensions).context_part()
        n_neurons, episode_length = check_n_neurons(n_neurons), check_episode_length(episode_length)
        # Refuse at once what could never be held (a context is about a kilobyte of
        # Python and NumPy objects besides its arrays), instead of generating for days.
        check_fits_in_memory(
            sum(sizes) * (CONTEXT_OVERHEAD_BYTES + n_neurons**2 + 3 * episode_length),
            f"{sum(sizes):,} contexts of {n_neurons} neurons", "generate fewer contexts",
        )  # fmt: skip
        taken = {context.weights.tobytes() for contexts in exclude for context in contexts}
        contexts = generate_distinct(
            sum(sizes), n_neurons, episode_length, seed if stream is None else [seed, stream],
            params, extensions, exclude=taken,
        )  # fmt: skip
        ends = list(accumulate(sizes))
        return [
            cls(contexts[end - size : end], params, seed, extensions)
            for size, end in zip(sizes, ends, strict=True)
        ]

    def __len__(self) -> int:
        return len(self._contexts)

    @overload
    def __getitem__(self, index: int) -> Context: ...

    @overload
    def __getitem__(self, index: slice) -> ContextSet: ...

    def __getitem__(self, index: int | slice) -> Context | ContextSet:
        if isinstance(index, slice):
            return ContextSet(self._contexts[index], self.params, self.seed, self.extensions)
        return self._contexts[index]

    def __iter__(self) -> Iterator[Context]:
        return iter(self._contexts)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ContextSet):
            return NotImplemented
        return (
            self.params == other.params
            and self.extensions == other.extensions
            and self._contexts == other._contexts
        )

    __hash__ = None

    def __repr__(self) -> str:
        extensions = self.extensions.to_dict(only_changed=True)
        return (
            f"ContextSet(size={len(self)}, n_neurons={self.n_neurons}, "
            f"episode_length={self.episode_length}, seed={self.seed}"
            + (f", extensions={extensions}" if extensions else "")
            + ")"
        )

    @property
    def n_neurons(self) -> int:
        """n, the number of neurons of every context."""
        return self._contexts[0].n_neurons

    @property
    def episode_length(self) -> int:
        """N, the episode length of every context."""
        return self._contexts[0].episode_length

    @property
    def n_observed(self) -> int:
        """k, the number of observable neurons of every context."""
        return self._contexts[0].n_observed

    def arrays(self) -> dict[str, np.ndarray]:
        """The set as stacked arrays: weights [S, n, n], targets [S], patterns [S, N],
        witnesses [S, N] (-2 where a context has no witness); with hidden neurons also
        hidden [S, h], with heterogeneous neurons thresholds_mV [S, n],
        time_constants_ms [S, n] and synaptic_scale [S, n, n]."""
        arrays = {
            "weights": np.stack([c.weights for c in self]).astype(np.int8),
            "targets": np.array([c.target for c in self], dtype=np.int64),
            "patterns": np.stack([c.pattern for c in self]).astype(bool),
            "witnesses": np.stack(
                [
                    c.witness if c.witness is not None else np.full(c.episode_length, -2)
                    for c in self
                ]
            ).astype(np.int16),
        }
        if self._contexts[0].hidden is not None:
            arrays["hidden"] = np.stack([c.hidden for c in self]).astype(np.int64)
        if self._contexts[0].heterogeneity is not None:
            for name in ("thresholds_mV", "time_constants_ms", "synaptic_scale"):
                arrays[name] = np.stack([getattr(c.heterogeneity, name) for c in self])
        return arrays

    def check_params(
        self, params: NeuronParams, whose: str, remedy: str, name: str = "the contexts"
    ) -> None:
        """Refuse ``params`` (``whose`` they are) unless they are those the set (``name``)
        was made with.

        The one check of every place handed neuron parameters beside contexts (the
        environments' ``params=``, a run's config): the contexts' patterns and
        witnesses hold only under their own params, so those are the params played. The
        error names each field that differs, then ``remedy``.
        """
        if params == self.params:
            return
        given, own = params.to_dict(), self.params.to_dict()
        differ = ", ".join(
            f"{key} {given[key]} (theirs: {own[key]})" for key in given if given[key] != own[key]
        )  # fmt: skip
        raise ValueError(
            f"params: {whose} differ from those {name} were made with: {differ}; {remedy}"
        )

    def topology_keys(self) -> list[bytes]:
        """One hashable key per context identifying its signed connectivity."""
        return [c.weights.astype(np.int8).tobytes() for c in self]

    def duplicate_topologies(self, other: ContextSet | None = None) -> list[tuple[int, int]]:
        """Index pairs sharing a topology: within this set, or between it and ``other``."""
        keys = self.topology_keys()
        if other is None:
            first_seen: dict[bytes, int] = {}
            pairs = []
            for index, key in enumerate(keys):
                if key in first_seen:
                    pairs.append((first_seen[key], index))
                first_seen.setdefault(key, index)
            return pairs
        other_index = {
            key: index for index, key in reversed(list(enumerate(other.topology_keys())))
        }
        return [(index, other_index[key]) for index, key in enumerate(keys) if key in other_index]

    def checksum(self, round_floats: bool = False) -> str:
        """SHA-256 over the arrays, parameters and extensions; equal sets, equal checksums.

        ``round_floats`` hashes float arrays (the heterogeneous neurons' parameters)
        rounded to 1e-9 as integers, so that a checksum pinned in code (the benchmark
        suite's) does not hang on the last bits of a float."""
        digest = hashlib.sha256()
        for name, array in sorted(self.arrays().items()):
            if round_floats and array.dtype.kind == "f":
                array = np.round(array * 1e9).astype(np.int64)
            digest.update(name.encode())
            digest.update(str(array.shape).encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(json.dumps(self.params.to_dict(), sort_keys=True).encode())
        extensions = self.extensions.to_dict(only_changed=True)
        if extensions:  # absent for the paper's sets, whose checksums stay as they were
            digest.update(json.dumps(extensions, sort_keys=True).encode())
        return digest.hexdigest()

    def save(self, path: str | os.PathLike) -> Path:
        """Write the set to one ``.npz`` file, atomically (a crash never leaves half a file).

        Sets without extensions are written as format version 1, as before; sets with
        context-level extensions as version 2 (``spikectl.contexts.file_format``).
        """
        path = Path(path)
        if path.is_dir():
            # Writing "folder.npz" beside it would not be where the caller looks.
            raise ValueError(f"{path} is a folder: give a file name (e.g. {path / 'contexts.npz'})")
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        metadata = {
            "size": len(self),
            "n_neurons": self.n_neurons,
            "episode_length": self.episode_length,
            "seed": self.seed,
            "params": self.params.to_dict(),
            "checksum": self.checksum(),
            "extensions": self.extensions.to_dict(only_changed=True),
        }
        return write_npz(path, self.arrays(), metadata)

    @classmethod
    def load(cls, path: str | os.PathLike) -> ContextSet:
        """Read a set written by :meth:`save`; a damaged or foreign file raises ContextFileError."""
        path = Path(path)
        arrays, metadata = read_npz(path)
        size = len(arrays["targets"])
        try:
            params = NeuronParams.from_dict(metadata["params"])
            hidden = arrays.get("hidden", [None] * size)
            heterogeneity = [None] * size
            if "thresholds_mV" in arrays:
                heterogeneity = [
                    Heterogeneity(*values)
                    for values in zip(arrays["thresholds_mV"], arrays["time_constants_ms"],
                                      arrays["synaptic_scale"], strict=True)
                ]  # fmt: skip
            contexts = [
                Context(weights, int(target), pattern, None if (witness == -2).all() else witness,
                        hidden_neurons, neurons)
                for weights, target, pattern, witness, hidden_neurons, neurons in zip(
                    arrays["weights"], arrays["targets"], arrays["patterns"],
                    arrays["witnesses"], hidden, heterogeneity, strict=True,
                )
            ]  # fmt: skip
            loaded = cls(contexts, params, metadata.get("seed"), metadata.get("extensions"))
        except (TypeError, ValueError, KeyError, IndexError, AttributeError) as error:
            raise ContextFileError(f"{path} holds an invalid context set: {error}") from error
        if loaded.checksum() != metadata.get("checksum"):
            raise ContextFileError(f"{path} is damaged: its checksum does not match its contents")
        if (len(loaded), loaded.n_neurons, loaded.episode_length) != (
            metadata.get("size"),
            metadata.get("n_neurons"),
            metadata.get("episode_length"),
        ):
            raise ContextFileError(f"{path} is inconsistent: its header does not match its arrays")
        # A checksum is recomputed as easily as a witness is changed: replay every witness
        # (generation checks them the same way), so a reference row never reports a
        # "witness" score for answers that do not produce the pattern.
        for index, context in enumerate(loaded):
            if context.witness is not None and not context.verify_witness(loaded.params):
                raise ContextFileError(
                    f"{path} is damaged: the witness of context {index} does not reproduce "
                    "its pattern in the target neuron"
                )
        return loaded


def _shape(context: Context) -> tuple[int, int, int, bool]:
    return (
        context.n_neurons,
        context.episode_length,
        context.n_observed,
        context.heterogeneity is not None,
    )
