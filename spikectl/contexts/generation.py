"""Procedurally generated contexts (docs/model.md): topology, target neuron, pattern.

A context (:class:`~spikectl.contexts.context.Context`) is the hidden connectivity of
one network, the neuron to control and the spike pattern it must produce, plus the
*witness*: an action sequence that produces that pattern from rest, which proves the
maximum return is reachable. With the context-level extensions
(``spikectl.neuron.extensions``) a context also fixes which neurons are hidden and the
per-neuron parameters of heterogeneous neurons.

Generation is a set of pure module-level functions of a ``numpy.random.Generator``;
:class:`~spikectl.contexts.context_set.ContextSet` and
:func:`~spikectl.contexts.context_set.make_splits` hold sequences of contexts and save
them to ``.npz`` files; this module does not import them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spikectl.contexts.context import Context, check_target
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
    params = NeuronParams() if params is None else params
    raise ImpossibleTaskError(
        f"no random action sequence of {episode_length} steps made neuron {target} spike in "
        f"{max_attempts} attempts: with these NeuronParams a release moves a neuron by "
        f"{params.synaptic_step_mV:g} mV and a stimulation by {params.stimulus_step_mV:g} mV, "
        f"{params.v_threshold_mV - params.v_rest_mV:g} mV below threshold at rest, so the target "
        "may never spike (check synaptic_current_pA, stimulus_current_pA, capacitance_pF)"
    )


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
    raise ImpossibleTaskError(
        f"no reachable target pattern in {MAX_TOPOLOGY_ATTEMPTS} networks (hidden or "
        "heterogeneous neurons may leave no observable neuron able to drive a target)"
    )


@dataclass(frozen=True)
class NeuronSetup:
    """What one network's neurons are beyond the shared neuron model, for
    :func:`make_context`: the indices of the ``hidden`` neurons (simulated, never
    observed nor stimulated) and each neuron's own parameters (``heterogeneity``, a
    :class:`~spikectl.neuron.extensions.Heterogeneity`); None: all observed, all alike."""

    hidden: Sequence[int] | np.ndarray | None = None
    heterogeneity: Heterogeneity | None = None


def make_context(
    weights: np.ndarray,
    target: int | None = None,
    pattern: np.ndarray | None = None,
    witness: np.ndarray | None = None,
    *,
    episode_length: int = 60,
    seed: int | None = 0,
    params: NeuronParams | None = None,
    neurons: NeuronSetup | None = None,
) -> Context:
    """Bring your own connectome: build a validated context from a connectivity matrix.

    Whatever is not given is generated as in docs/model.md from ``seed``: the target
    (uniform among neurons with an excitatory input) and the pattern with its
    witness (random legal actions from rest, never a hidden neuron). ``neurons`` says
    which neurons are hidden and each neuron's own parameters (:class:`NeuronSetup`;
    None: all observed, all alike). A given
    witness must reproduce the given pattern under ``params`` and the neurons' own ones;
    a given pattern without a witness is accepted as is (its reachability is then
    unknown and ``witness`` is None).
    """
    weight_matrix = as_weight_batch(weights)[0].astype(np.int8)
    neurons = NeuronSetup() if neurons is None else neurons
    if not isinstance(neurons, NeuronSetup):
        raise TypeError(f"neurons must be a NeuronSetup or None, got {type(neurons).__name__}")
    hidden, heterogeneity = neurons.hidden, neurons.heterogeneity
    rng = np.random.default_rng(seed)
    if target is None:
        candidates = target_candidates(weight_matrix)
        if candidates.size == 0:
            raise ValueError("no neuron has an excitatory input, so no target can be controlled")
        target = int(rng.choice(candidates))
    check_target(target, weight_matrix.shape[0])
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


def is_int(value: Any) -> bool:
    """True for Python and NumPy integers, False for booleans (which Python calls ints)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


class ImpossibleTaskError(ValueError, RuntimeError):
    """The neuron model cannot (or almost never) make a target spike: no context exists.
    A ValueError for the user (the parameters are the problem); a RuntimeError for the
    generator, which draws another network after one whose target it could not drive."""


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


def generate_distinct(
    size: int,
    n_neurons: int,
    episode_length: int,
    seed: int | list[int],
    params: NeuronParams | None,
    extensions: Extensions | None = None,
    exclude: set[bytes] = frozenset(),
) -> list[Context]:
    """``size`` contexts with pairwise distinct topologies (none in ``exclude``, the
    weight matrices' bytes) drawn from ``default_rng(seed)``; a ValueError when
    :data:`MAX_TOPOLOGY_ATTEMPTS` draws in a row repeat a topology."""
    n_neurons = check_n_neurons(n_neurons)
    episode_length = check_episode_length(episode_length)
    if params is not None and not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams or None, got {type(params).__name__}")
    rng = np.random.default_rng(seed)
    contexts: list[Context] = []
    seen: set[bytes] = set(exclude)
    rejected_in_a_row = 0
    while len(contexts) < size:
        context = generate_context(rng, n_neurons, episode_length, params, extensions)
        key = context.weights.tobytes()
        if key in seen:
            rejected_in_a_row += 1
            if rejected_in_a_row > MAX_TOPOLOGY_ATTEMPTS:
                raise ValueError(
                    f"could not find {size} distinct topologies of {n_neurons} neurons: "
                    "ask for fewer contexts or larger networks"
                )
            continue
        rejected_in_a_row = 0
        seen.add(key)
        contexts.append(context)
    return contexts
