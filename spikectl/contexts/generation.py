"""Procedurally generated contexts (docs/model.md): topology, target neuron, pattern.

A context is the hidden connectivity of one network, the neuron to control and the
spike pattern it must produce, plus the *witness*: an action sequence that produces
that pattern from rest, which proves the maximum return is reachable. With the
context-level extensions (``spikectl.neuron.extensions``) a context also fixes which
neurons are hidden and the per-neuron parameters of heterogeneous neurons.

Generation is a set of pure module-level functions of a ``numpy.random.Generator``;
:class:`~spikectl.contexts.context_set.ContextSet` and
:func:`~spikectl.contexts.context_set.make_splits` hold sequences of contexts and save
them to ``.npz`` files; this module does not import them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from spikectl.neuron.extensions import Extensions, Heterogeneity, draw_heterogeneity, draw_hidden
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, as_weight_batch, simulate

EXCITATORY_PROBABILITY = 0.8
"""Probability that a neuron is excitatory (Dale's law: all its outgoing edges are +1)."""

# (largest distance |i - j| of the band, connection probability); beyond the last: 0.01.
CONNECTION_PROBABILITY_BANDS = ((4, 0.3), (8, 0.2), (12, 0.1))
LONG_RANGE_CONNECTION_PROBABILITY = 0.01

MAX_N_NEURONS = 1024
"""The largest network size supported (docs/extensions.md, "Larger networks"): memory
grows as n^2 per context and per environment, and sizes above are untested."""
MAX_EPISODE_LENGTH = 100_000
"""The longest episode supported (steps); the paper's are 60."""

MAX_PATTERN_ATTEMPTS = 10_000
MAX_TOPOLOGY_ATTEMPTS = 10_000
EXTENDED_PATTERN_ATTEMPTS = 1_000
"""With hidden or heterogeneous neurons a target may be unreachable from the observable
neurons: after this many action sequences without a spike a new topology is drawn."""


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
    check_n_neurons(n_neurons)
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


def excitatory_path_exists(weights: np.ndarray, target: int, hidden: np.ndarray) -> bool:
    """True when a path of excitatory edges leads from a stimulable neuron to the target.

    Necessary for the target to spike at all when some neurons are hidden (a breadth-
    first search over G > 0, O(n^2)).
    """
    excitatory = np.asarray(weights) > 0
    reached = np.ones(excitatory.shape[0], dtype=bool)
    reached[hidden] = False
    reached[target] = False
    frontier = reached.copy()
    while frontier.any():
        frontier = excitatory[frontier].any(axis=0) & ~reached
        reached |= frontier
    return bool(reached[target])


def legal_actions(
    n_neurons: int,
    target: int,
    allow_target_action: bool = False,
    hidden: np.ndarray | None = None,
) -> np.ndarray:
    """The agent's action set: do nothing (-1) and every observable neuron but the target.

    Neuron indices (simulator actions); ``hidden`` neurons are never actions.
    """
    actions = np.arange(DO_NOTHING, n_neurons)
    keep = np.ones(actions.shape, dtype=bool)
    if not allow_target_action:
        keep &= actions != target
    if hidden is not None:
        keep &= ~np.isin(actions, hidden)
    return actions[keep]


def generate_pattern(
    weights: np.ndarray,
    target: int,
    episode_length: int,
    rng: np.random.Generator,
    params: NeuronParams | None = None,
    *,
    hidden: np.ndarray | None = None,
    heterogeneity: Heterogeneity | None = None,
    max_attempts: int = MAX_PATTERN_ATTEMPTS,
) -> tuple[np.ndarray, np.ndarray]:
    """Target pattern [N] bool and its witness actions [N] int16 (neuron indices).

    From rest, uniformly random legal actions (never a ``hidden`` neuron) are
    simulated, with the ``heterogeneity`` of the network if any, and the target's
    spikes recorded; the actions are redrawn until the pattern has at least one spike.
    """
    weights = np.asarray(weights)
    actions = legal_actions(weights.shape[0], target, hidden=hidden)
    extra = {} if heterogeneity is None else heterogeneity.simulate_kwargs()
    for _ in range(max_attempts):
        witness = rng.choice(actions, size=episode_length)
        _, spikes = simulate(weights, witness, params, **extra)  # [N, n]
        pattern = spikes[:, target]
        if pattern.any():
            return pattern.copy(), witness.astype(np.int16)
    raise RuntimeError(f"no action sequence made neuron {target} spike in {max_attempts} attempts")


def generate_context(
    rng: np.random.Generator,
    n_neurons: int = 8,
    episode_length: int = 60,
    params: NeuronParams | None = None,
    extensions: Extensions | Mapping[str, Any] | None = None,
) -> Context:
    """Draw one context: a topology with a valid target, the target, a pattern, a witness.

    With context-level ``extensions`` the hidden neurons and then the heterogeneous
    parameters are drawn after the target and before the pattern; without them no
    extra random number is drawn, so the paper's contexts are unchanged.
    """
    check_episode_length(episode_length)
    extensions = Extensions.coerce(extensions)
    hidden_count = extensions.hidden_count(n_neurons)
    extended = hidden_count > 0 or extensions.heterogeneous
    for _ in range(MAX_TOPOLOGY_ATTEMPTS):
        for _ in range(MAX_TOPOLOGY_ATTEMPTS):
            weights = generate_topology(n_neurons, rng)
            candidates = target_candidates(weights)
            if candidates.size:
                break
        else:
            raise RuntimeError(
                f"no topology with an excitatory edge in {MAX_TOPOLOGY_ATTEMPTS} draws"
            )
        target = int(rng.choice(candidates))
        hidden = draw_hidden(rng, n_neurons, target, hidden_count)
        heterogeneity = draw_heterogeneity(rng, weights, params or NeuronParams(), extensions)
        if hidden is not None and not excitatory_path_exists(weights, target, hidden):
            continue  # no observable neuron can drive the target: draw a new network
        try:
            pattern, witness = generate_pattern(
                weights, target, episode_length, rng, params, hidden=hidden,
                heterogeneity=heterogeneity,
                max_attempts=EXTENDED_PATTERN_ATTEMPTS if extended else MAX_PATTERN_ATTEMPTS,
            )  # fmt: skip
        except RuntimeError:
            if not extended:
                raise
            continue  # unreachable from the observable neurons: draw a new network
        return Context(weights, target, pattern, witness, hidden, heterogeneity)
    raise RuntimeError(f"no reachable target pattern in {MAX_TOPOLOGY_ATTEMPTS} networks")


@dataclass(frozen=True, eq=False)
class Context:
    """One task: hidden connectivity, the observable target and pattern, and a witness.

    Attributes:
        weights: [n, n] int8 signed connectivity, row = presynaptic (never observable).
        target: the neuron to control (a neuron index).
        pattern: [N] bool, the steps at which the target must spike.
        witness: [N] int16 actions (neuron indices) that produce ``pattern`` from rest,
            or None for a user-supplied pattern whose reachability is unknown.
        hidden: sorted int64 indices of the neurons that are simulated but neither
            observed nor stimulable (an extension), or None. Never the target.
        heterogeneity: per-neuron and per-synapse parameters (an extension), or None
            for the paper's identical neurons.
    """

    weights: np.ndarray
    target: int
    pattern: np.ndarray
    witness: np.ndarray | None = None
    hidden: np.ndarray | None = None
    heterogeneity: Heterogeneity | None = None

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
        self._check_extensions(n)
        if self.witness is not None:
            witness = np.asarray(self.witness)
            if witness.shape != pattern.shape or not np.issubdtype(witness.dtype, np.integer):
                raise ValueError(
                    f"witness must be integer actions of shape {pattern.shape}, "
                    f"got {witness.dtype} {witness.shape}"
                )
            if witness.min() < DO_NOTHING or witness.max() >= n:
                raise ValueError(f"witness actions must lie in -1..{n - 1}")
            if self.hidden is not None and np.isin(witness, self.hidden).any():
                raise ValueError("witness actions must not stimulate hidden neurons")
            object.__setattr__(self, "witness", _readonly(witness.astype(np.int16)))

    def _check_extensions(self, n: int) -> None:
        if self.hidden is not None:
            hidden = np.asarray(self.hidden)
            if hidden.ndim != 1 or (hidden.size and not np.issubdtype(hidden.dtype, np.integer)):
                raise ValueError(f"hidden must be a 1-D array of neuron indices, got {hidden!r}")
            hidden = np.unique(hidden.astype(np.int64))
            if hidden.size != np.asarray(self.hidden).size:
                raise ValueError("hidden neurons must be distinct")
            if hidden.size and (hidden.min() < 0 or hidden.max() >= n):
                raise ValueError(f"hidden neurons must be neuron indices in 0..{n - 1}")
            if self.target in hidden:
                raise ValueError(f"the target neuron {self.target} cannot be hidden")
            if n - hidden.size < 2:
                raise ValueError("at least 2 neurons must be observable (the target and one more)")
            object.__setattr__(self, "hidden", _readonly(hidden) if hidden.size else None)
        if self.heterogeneity is not None:
            if not isinstance(self.heterogeneity, Heterogeneity):
                raise TypeError(
                    f"heterogeneity must be a Heterogeneity or None, got {self.heterogeneity!r}"
                )
            if self.heterogeneity.n_neurons != n:
                raise ValueError(
                    f"heterogeneity is for {self.heterogeneity.n_neurons} neurons, not {n}"
                )

    @property
    def n_neurons(self) -> int:
        return self.weights.shape[0]

    @property
    def episode_length(self) -> int:
        return self.pattern.shape[0]

    @property
    def observable(self) -> np.ndarray:
        """[k] increasing indices of the observable neurons (all n without hidden ones)."""
        everyone = np.arange(self.n_neurons)
        return everyone if self.hidden is None else np.setdiff1d(everyone, self.hidden)

    @property
    def n_observed(self) -> int:
        """k, the number of observable neurons."""
        return self.n_neurons - (0 if self.hidden is None else self.hidden.size)

    @property
    def observed_target(self) -> int:
        """The target's index among the observable neurons (what the agent sees)."""
        return int(np.searchsorted(self.observable, self.target))

    @property
    def agent_witness(self) -> np.ndarray | None:
        """The witness as environment actions (indices among the observable neurons)."""
        if self.witness is None or self.hidden is None:
            return self.witness
        observed = np.searchsorted(self.observable, self.witness)
        return np.where(self.witness >= 0, observed, DO_NOTHING).astype(np.int16)

    def simulate_kwargs(self) -> dict[str, np.ndarray]:
        """Keyword arguments of :func:`spikectl.simulate` for this network's neurons."""
        return {} if self.heterogeneity is None else self.heterogeneity.simulate_kwargs()

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Context):
            return NotImplemented
        return (
            self.target == other.target
            and np.array_equal(self.weights, other.weights)
            and np.array_equal(self.pattern, other.pattern)
            and _optional_equal(self.witness, other.witness)
            and _optional_equal(self.hidden, other.hidden)
            and self.heterogeneity == other.heterogeneity
        )

    __hash__ = None  # mutable-looking arrays inside; compare with ==

    def verify_witness(self, params: NeuronParams | None = None) -> bool:
        """True when replaying the witness from rest reproduces the pattern exactly."""
        if self.witness is None:
            return False
        witness = self.witness.astype(np.int64)
        _, spikes = simulate(self.weights, witness, params, **self.simulate_kwargs())
        return bool(np.array_equal(spikes[:, self.target], self.pattern))


def _optional_equal(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(a, b))


def make_context(
    weights: np.ndarray,
    target: int | None = None,
    pattern: np.ndarray | None = None,
    witness: np.ndarray | None = None,
    *,
    episode_length: int = 60,
    seed: int | None = 0,
    params: NeuronParams | None = None,
    hidden: np.ndarray | None = None,
    heterogeneity: Heterogeneity | None = None,
) -> Context:
    """Bring your own connectome: build a validated context from a connectivity matrix.

    Whatever is not given is generated as in docs/model.md from ``seed``: the target
    (uniform among neurons with an excitatory input) and the pattern with its
    witness (random legal actions from rest, never a ``hidden`` neuron). A given
    witness must reproduce the given pattern under ``params`` and ``heterogeneity``;
    a given pattern without a witness is accepted as is (its reachability is then
    unknown and ``witness`` is None).
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
        check_episode_length(episode_length)
        if hidden is not None and target in np.asarray(hidden):
            raise ValueError(f"the target neuron {target} cannot be hidden")
        pattern, witness = generate_pattern(
            weight_matrix, target, episode_length, rng, params, hidden=hidden,
            heterogeneity=heterogeneity,
        )  # fmt: skip
    context = Context(weight_matrix, target, pattern, witness, hidden, heterogeneity)
    if witness is not None and not context.verify_witness(params):
        raise ValueError("the witness does not reproduce the pattern in the target neuron")
    return context


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array)  # a private copy, so the caller's array cannot change us
    array.flags.writeable = False
    return array


def _check_target(target: int, n_neurons: int) -> None:
    if isinstance(target, (bool, np.bool_)) or not isinstance(target, (int, np.integer)):
        raise TypeError(f"target must be an integer neuron index, got {target!r}")
    if not 0 <= target < n_neurons:
        raise ValueError(f"target {target} is not a neuron index in 0..{n_neurons - 1}")


def is_int(value: Any) -> bool:
    """True for Python and NumPy integers, False for booleans (which Python calls ints)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def check_n_neurons(n_neurons: int) -> int:
    if not is_int(n_neurons) or not 2 <= n_neurons <= MAX_N_NEURONS:
        raise ValueError(
            f"n_neurons must be an integer in 2..{MAX_N_NEURONS} (MAX_N_NEURONS), got {n_neurons!r}"
        )
    return int(n_neurons)


def check_episode_length(episode_length: int) -> int:
    if not is_int(episode_length) or not 2 <= episode_length <= MAX_EPISODE_LENGTH:
        raise ValueError(
            f"episode_length must be an integer in 2..{MAX_EPISODE_LENGTH} "
            f"(MAX_EPISODE_LENGTH), got {episode_length!r}"
        )
    return int(episode_length)


def check_size(size: int, name: str = "size") -> int:
    if not is_int(size) or size < 1:
        raise ValueError(f"{name} must be a positive integer, got {size!r}")
    return int(size)


def check_seed(seed: Any, name: str = "seed") -> int:
    """A generation seed: a non-negative Python or NumPy integer."""
    if not is_int(seed) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {seed!r}")
    return int(seed)
