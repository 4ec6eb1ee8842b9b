"""Procedurally generated contexts (SPEC section 2): topology, target neuron, pattern.

A context is the hidden connectivity of one network, the neuron to control and the
spike pattern it must produce, plus the *witness*: an action sequence that produces
that pattern from rest, which proves the maximum return is reachable.

Generation is a set of pure module-level functions of a ``numpy.random.Generator``;
:class:`ContextSet` holds a sequence of contexts with the parameters they were made
with, and saves to / loads from one ``.npz`` file with a format version and a checksum.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

import numpy as np

from spikectl.params import NeuronParams
from spikectl.simulator import DO_NOTHING, as_weight_batch, simulate

EXCITATORY_PROBABILITY = 0.8
"""Probability that a neuron is excitatory (Dale's law: all its outgoing edges are +1)."""

# (largest distance |i - j| of the band, connection probability); beyond the last: 0.01.
CONNECTION_PROBABILITY_BANDS = ((4, 0.3), (8, 0.2), (12, 0.1))
LONG_RANGE_CONNECTION_PROBABILITY = 0.01

MAX_PATTERN_ATTEMPTS = 10_000
MAX_TOPOLOGY_ATTEMPTS = 10_000

FORMAT_NAME = "spikectl.ContextSet"
FORMAT_VERSION = 1


class ContextFileError(ValueError):
    """A context-set file that is unreadable, damaged, foreign or of another version."""


def connection_probability(distance: np.ndarray) -> np.ndarray:
    """Probability of a connection i -> j as a function of d = |i - j| (Appendix B)."""
    distance = np.asarray(distance)
    probability = np.full(distance.shape, LONG_RANGE_CONNECTION_PROBABILITY)
    for max_distance, band_probability in reversed(CONNECTION_PROBABILITY_BANDS):
        probability = np.where(distance <= max_distance, band_probability, probability)
    return probability


def generate_topology(n_neurons: int, rng: np.random.Generator) -> np.ndarray:
    """Signed connectivity G [n, n] int8: neurons on a line, distance-banded edges.

    Each neuron is excitatory with probability 0.8, else inhibitory, and its sign
    applies to all of its outgoing edges; each ordered pair i != j is connected
    independently with the probability of its distance band.
    """
    _check_n_neurons(n_neurons)
    index = np.arange(n_neurons)
    distance = np.abs(index[:, None] - index[None, :])  # [n, n]
    connected = rng.random((n_neurons, n_neurons)) < connection_probability(distance)
    np.fill_diagonal(connected, False)
    excitatory = rng.random(n_neurons) < EXCITATORY_PROBABILITY  # [n]
    sign = np.where(excitatory, 1, -1).astype(np.int8)
    return (connected * sign[:, None]).astype(np.int8)


def target_candidates(weights: np.ndarray) -> np.ndarray:
    """Neurons with at least one incoming excitatory connection."""
    return np.flatnonzero((np.asarray(weights) > 0).any(axis=0))


def legal_actions(n_neurons: int, target: int, allow_target_action: bool = False) -> np.ndarray:
    """The agent's action set: do nothing (-1) and every neuron but the target."""
    actions = np.arange(DO_NOTHING, n_neurons)
    if allow_target_action:
        return actions
    return actions[actions != target]


def generate_pattern(
    weights: np.ndarray,
    target: int,
    episode_length: int,
    rng: np.random.Generator,
    params: NeuronParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Target pattern [N] bool and its witness actions [N] int16.

    From rest, uniformly random legal actions are simulated and the target's spikes
    recorded; the actions are redrawn until the pattern has at least one spike.
    """
    weights = np.asarray(weights)
    actions = legal_actions(weights.shape[0], target)
    for _ in range(MAX_PATTERN_ATTEMPTS):
        witness = rng.choice(actions, size=episode_length)
        _, spikes = simulate(weights, witness, params)  # [N, n]
        pattern = spikes[:, target]
        if pattern.any():
            return pattern.copy(), witness.astype(np.int16)
    raise RuntimeError(
        f"no action sequence made neuron {target} spike in {MAX_PATTERN_ATTEMPTS} attempts"
    )


def generate_context(
    rng: np.random.Generator,
    n_neurons: int = 8,
    episode_length: int = 60,
    params: NeuronParams | None = None,
) -> Context:
    """Draw one context: a topology with a valid target, the target, a pattern, a witness."""
    _check_episode_length(episode_length)
    for _ in range(MAX_TOPOLOGY_ATTEMPTS):
        weights = generate_topology(n_neurons, rng)
        candidates = target_candidates(weights)
        if candidates.size:
            break
    else:
        raise RuntimeError(f"no topology with an excitatory edge in {MAX_TOPOLOGY_ATTEMPTS} draws")
    target = int(rng.choice(candidates))
    pattern, witness = generate_pattern(weights, target, episode_length, rng, params)
    return Context(weights=weights, target=target, pattern=pattern, witness=witness)


@dataclass(frozen=True, eq=False)
class Context:
    """One task: hidden connectivity, the observable target and pattern, and a witness.

    Attributes:
        weights: [n, n] int8 signed connectivity, row = presynaptic (never observable).
        target: the neuron to control.
        pattern: [N] bool, the steps at which the target must spike.
        witness: [N] int16 actions that produce ``pattern`` from rest, or None for a
            user-supplied pattern whose reachability is unknown.
    """

    weights: np.ndarray
    target: int
    pattern: np.ndarray
    witness: np.ndarray | None = None

    def __post_init__(self) -> None:
        weights = as_weight_batch(self.weights)[0].astype(np.int8)
        n = weights.shape[0]
        if n < 2:
            raise ValueError(f"a context needs at least 2 neurons, got {n}")
        _check_target(self.target, n)
        pattern = np.asarray(self.pattern)
        if pattern.ndim != 1:
            raise ValueError(f"pattern must be 1-D [episode_length], got shape {pattern.shape}")
        if not np.all(np.isin(pattern, (0, 1))):
            raise ValueError("pattern must contain only 0/1 or False/True")
        pattern = pattern.astype(bool)
        spikes = int(pattern.sum())
        if not 1 <= spikes <= pattern.size - 1:
            raise ValueError(
                f"pattern must have between 1 and {pattern.size - 1} spikes (the reward "
                f"divides by both counts), got {spikes}"
            )
        object.__setattr__(self, "weights", _readonly(weights))
        object.__setattr__(self, "target", int(self.target))
        object.__setattr__(self, "pattern", _readonly(pattern))
        if self.witness is not None:
            witness = np.asarray(self.witness)
            if witness.shape != pattern.shape or not np.issubdtype(witness.dtype, np.integer):
                raise ValueError(
                    f"witness must be integer actions of shape {pattern.shape}, "
                    f"got {witness.dtype} {witness.shape}"
                )
            if witness.min() < DO_NOTHING or witness.max() >= n:
                raise ValueError(f"witness actions must lie in -1..{n - 1}")
            object.__setattr__(self, "witness", _readonly(witness.astype(np.int16)))

    @property
    def n_neurons(self) -> int:
        return self.weights.shape[0]

    @property
    def episode_length(self) -> int:
        return self.pattern.shape[0]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Context):
            return NotImplemented
        witnesses_equal = (self.witness is None and other.witness is None) or (
            self.witness is not None
            and other.witness is not None
            and np.array_equal(self.witness, other.witness)
        )
        return (
            self.target == other.target
            and np.array_equal(self.weights, other.weights)
            and np.array_equal(self.pattern, other.pattern)
            and witnesses_equal
        )

    __hash__ = None  # mutable-looking arrays inside; compare with ==

    def verify_witness(self, params: NeuronParams | None = None) -> bool:
        """True when replaying the witness from rest reproduces the pattern exactly."""
        if self.witness is None:
            return False
        _, spikes = simulate(self.weights, self.witness.astype(np.int64), params)
        return bool(np.array_equal(spikes[:, self.target], self.pattern))


def make_context(
    weights: np.ndarray,
    target: int | None = None,
    pattern: np.ndarray | None = None,
    witness: np.ndarray | None = None,
    *,
    episode_length: int = 60,
    seed: int | None = 0,
    params: NeuronParams | None = None,
) -> Context:
    """Bring your own connectome: build a validated context from a connectivity matrix.

    Whatever is not given is generated as in SPEC 2 from ``seed``: the target
    (uniform among neurons with an excitatory input) and the pattern with its
    witness (random legal actions from rest). A given witness must reproduce the
    given pattern under ``params``; a given pattern without a witness is accepted
    as is (its reachability is then unknown and ``witness`` is None).
    """
    weight_matrix = as_weight_batch(weights)[0].astype(np.int8)
    rng = np.random.default_rng(seed)
    if target is None:
        candidates = target_candidates(weight_matrix)
        if candidates.size == 0:
            raise ValueError("no neuron has an excitatory input, so no target can be controlled")
        target = int(rng.choice(candidates))
    _check_target(target, weight_matrix.shape[0])
    if pattern is None:
        if witness is not None:
            raise ValueError("a witness without a pattern: pass the pattern it produces")
        _check_episode_length(episode_length)
        pattern, witness = generate_pattern(weight_matrix, target, episode_length, rng, params)
    context = Context(weight_matrix, target, pattern, witness)
    if witness is not None and not context.verify_witness(params):
        raise ValueError("the witness does not reproduce the pattern in the target neuron")
    return context


class ContextSet(Sequence[Context]):
    """An immutable sequence of contexts of one size and episode length.

    Build one with :meth:`generate` (or :func:`make_splits`), from your own
    contexts, or with :meth:`load`. ``params`` are the model parameters the
    witnesses were made with; ``seed`` is the generation seed when there is one.
    """

    def __init__(
        self,
        contexts: Sequence[Context],
        params: NeuronParams | None = None,
        seed: int | None = None,
    ) -> None:
        self._contexts = tuple(contexts)
        if not self._contexts:
            raise ValueError("a ContextSet needs at least one context")
        for index, context in enumerate(self._contexts):
            if not isinstance(context, Context):
                raise TypeError(f"item {index} is a {type(context).__name__}, not a Context")
        first = self._contexts[0]
        for index, context in enumerate(self._contexts):
            if (context.n_neurons, context.episode_length) != (
                first.n_neurons,
                first.episode_length,
            ):
                raise ValueError(
                    f"context {index} has {context.n_neurons} neurons and episode length "
                    f"{context.episode_length}; context 0 has {first.n_neurons} and "
                    f"{first.episode_length}: a set holds one shape"
                )
        self.params = NeuronParams() if params is None else params
        self.seed = seed

    @classmethod
    def generate(
        cls,
        size: int,
        n_neurons: int = 8,
        episode_length: int = 60,
        seed: int = 0,
        params: NeuronParams | None = None,
    ) -> ContextSet:
        """``size`` contexts with pairwise distinct topologies, reproducible from ``seed``.

        Sets are prefix-stable: ``generate(10, seed=s)`` is the first 10 contexts of
        ``generate(100, seed=s)``.
        """
        _check_size(size)
        contexts = _generate_unique(size, n_neurons, episode_length, seed, params)
        return cls(contexts, params, seed)

    def __len__(self) -> int:
        return len(self._contexts)

    @overload
    def __getitem__(self, index: int) -> Context: ...

    @overload
    def __getitem__(self, index: slice) -> ContextSet: ...

    def __getitem__(self, index: int | slice) -> Context | ContextSet:
        if isinstance(index, slice):
            return ContextSet(self._contexts[index], self.params, self.seed)
        return self._contexts[index]

    def __iter__(self) -> Iterator[Context]:
        return iter(self._contexts)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ContextSet):
            return NotImplemented
        return self.params == other.params and self._contexts == other._contexts

    __hash__ = None

    def __repr__(self) -> str:
        return (
            f"ContextSet(size={len(self)}, n_neurons={self.n_neurons}, "
            f"episode_length={self.episode_length}, seed={self.seed})"
        )

    @property
    def n_neurons(self) -> int:
        return self._contexts[0].n_neurons

    @property
    def episode_length(self) -> int:
        return self._contexts[0].episode_length

    def arrays(self) -> dict[str, np.ndarray]:
        """The set as stacked arrays: weights [S, n, n], targets [S], patterns [S, N],
        witnesses [S, N] (-2 where a context has no witness)."""
        return {
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

    def checksum(self) -> str:
        """SHA-256 over the arrays and parameters; equal sets have equal checksums."""
        digest = hashlib.sha256()
        for name, array in sorted(self.arrays().items()):
            digest.update(name.encode())
            digest.update(str(array.shape).encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(json.dumps(self.params.to_dict(), sort_keys=True).encode())
        return digest.hexdigest()

    def save(self, path: str | os.PathLike) -> Path:
        """Write the set to one ``.npz`` file, atomically (a crash never leaves half a file)."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        metadata = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "size": len(self),
            "n_neurons": self.n_neurons,
            "episode_length": self.episode_length,
            "seed": self.seed,
            "params": self.params.to_dict(),
            "checksum": self.checksum(),
        }
        path.parent.mkdir(parents=True, exist_ok=True)
        descriptor, temporary = tempfile.mkstemp(
            dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"
        )
        try:
            with os.fdopen(descriptor, "wb") as handle:
                np.savez_compressed(
                    handle, metadata=np.array(json.dumps(metadata)), **self.arrays()
                )
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(temporary, path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> ContextSet:
        """Read a set written by :meth:`save`; a damaged or foreign file raises ContextFileError."""
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"context set file not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as error:
            raise ContextFileError(
                f"{path} is not a readable spikectl context set: {error}"
            ) from error
        expected = {"metadata", "weights", "targets", "patterns", "witnesses"}
        if set(arrays) != expected:
            raise ContextFileError(
                f"{path} is not a spikectl context set (arrays {sorted(arrays)}, "
                f"expected {sorted(expected)})"
            )
        metadata = _parse_metadata(path, arrays.pop("metadata"))
        try:
            params = NeuronParams.from_dict(metadata["params"])
            contexts = [
                Context(weights, int(target), pattern, None if (witness == -2).all() else witness)
                for weights, target, pattern, witness in zip(
                    arrays["weights"],
                    arrays["targets"],
                    arrays["patterns"],
                    arrays["witnesses"],
                    strict=True,
                )
            ]
            loaded = cls(contexts, params, metadata.get("seed"))
        except (TypeError, ValueError) as error:
            raise ContextFileError(f"{path} holds an invalid context set: {error}") from error
        if loaded.checksum() != metadata.get("checksum"):
            raise ContextFileError(f"{path} is damaged: its checksum does not match its contents")
        if (len(loaded), loaded.n_neurons, loaded.episode_length) != (
            metadata.get("size"),
            metadata.get("n_neurons"),
            metadata.get("episode_length"),
        ):
            raise ContextFileError(f"{path} is inconsistent: its header does not match its arrays")
        return loaded


def make_splits(
    n_train: int = 100,
    n_test: int = 100,
    n_neurons: int = 8,
    episode_length: int = 60,
    seed: int = 0,
    params: NeuronParams | None = None,
) -> tuple[ContextSet, ContextSet]:
    """A training and a test set with no topology shared within or across them.

    The test set is drawn first and the training set continues the same stream, so
    for one seed the test set does not depend on ``n_train`` and smaller training
    sets are prefixes of larger ones (the paper's Figure 5 compares sizes on one
    test set).
    """
    _check_size(n_train, "n_train")
    _check_size(n_test, "n_test")
    contexts = _generate_unique(n_test + n_train, n_neurons, episode_length, seed, params)
    test = ContextSet(contexts[:n_test], params, seed)
    train = ContextSet(contexts[n_test:], params, seed)
    return train, test


def _generate_unique(
    size: int, n_neurons: int, episode_length: int, seed: int, params: NeuronParams | None
) -> list[Context]:
    _check_n_neurons(n_neurons)
    _check_episode_length(episode_length)
    rng = np.random.default_rng(seed)
    contexts: list[Context] = []
    seen: set[bytes] = set()
    rejected_in_a_row = 0
    while len(contexts) < size:
        context = generate_context(rng, n_neurons, episode_length, params)
        key = context.weights.tobytes()
        if key in seen:
            rejected_in_a_row += 1
            if rejected_in_a_row > MAX_TOPOLOGY_ATTEMPTS:
                raise RuntimeError(
                    f"could not find {size} distinct topologies of {n_neurons} neurons"
                )
            continue
        rejected_in_a_row = 0
        seen.add(key)
        contexts.append(context)
    return contexts


def _parse_metadata(path: Path, raw: np.ndarray) -> dict[str, Any]:
    try:
        metadata = json.loads(str(raw))
    except (json.JSONDecodeError, TypeError) as error:
        raise ContextFileError(f"{path} has an unreadable header: {error}") from error
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT_NAME:
        raise ContextFileError(f"{path} is not a spikectl context set (no {FORMAT_NAME} header)")
    version = metadata.get("format_version")
    if version != FORMAT_VERSION:
        raise ContextFileError(
            f"{path} has context-set format version {version}; this spikectl reads version "
            f"{FORMAT_VERSION}"
        )
    return metadata


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array)  # a private copy, so the caller's array cannot change us
    array.flags.writeable = False
    return array


def _check_target(target: int, n_neurons: int) -> None:
    if isinstance(target, (bool, np.bool_)) or not isinstance(target, (int, np.integer)):
        raise TypeError(f"target must be an integer neuron index, got {target!r}")
    if not 0 <= target < n_neurons:
        raise ValueError(f"target {target} is not a neuron index in 0..{n_neurons - 1}")


def _check_n_neurons(n_neurons: int) -> None:
    if isinstance(n_neurons, bool) or int(n_neurons) != n_neurons or n_neurons < 2:
        raise ValueError(f"n_neurons must be an integer >= 2, got {n_neurons!r}")


def _check_episode_length(episode_length: int) -> None:
    if (
        isinstance(episode_length, bool)
        or int(episode_length) != episode_length
        or episode_length < 2
    ):
        raise ValueError(f"episode_length must be an integer >= 2, got {episode_length!r}")


def _check_size(size: int, name: str = "size") -> None:
    if isinstance(size, bool) or int(size) != size or size < 1:
        raise ValueError(f"{name} must be a positive integer, got {size!r}")
