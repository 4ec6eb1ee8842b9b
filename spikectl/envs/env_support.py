"""What the single and the vector environment share (docs/environment.md).

Resolving the constructor arguments (:func:`resolve_setup`; generated sets:
:class:`GeneratedContexts`) to a :class:`ContextSet` and the effective
:class:`~spikectl.neuron.extensions.Extensions`, the per-context lookup tables
(:class:`ContextTables`), the reward formula (:func:`step_rewards`), the spaces and the
action checks.
"""

from __future__ import annotations

import functools
import operator
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from spikectl.contexts import Context, ContextSet, make_splits
from spikectl.contexts.generation import check_seed, check_size, is_int
from spikectl.envs.latency import IN_FLIGHT_KEY, in_flight_space
from spikectl.envs.sensing import RECORDED_KEY, sensed_key, sensed_space
from spikectl.neuron.extensions import CONTEXT_FIELDS, EnvironmentEffects, Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, neuron_parameters

MAX_REWARD = 0.5
"""R_max: the return of an episode's correct spikes, and separately of its correct silences."""
DEFAULT_N_NEURONS = 8
DEFAULT_EPISODE_LENGTH = 60
SPLITS = ("train", "test")
RENDER_MODES = ["ansi", "rgb_array"]
RENDER_FPS = 10
"""Frames per second of recorded videos: a 60 ms episode plays for 6 s."""


def step_rewards(patterns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reward of each step [..., N] if the target spikes, and if it stays silent.

    With m spikes in a pattern of N steps: R_max / m for a wanted spike,
    R_max / (N - m) for a wanted silence, 0 otherwise (docs/environment.md).
    """
    wanted = np.asarray(patterns).astype(bool)
    episode_length = wanted.shape[-1]
    m = wanted.sum(axis=-1, keepdims=True)
    if np.any(m == 0) or np.any(m == episode_length):
        raise ValueError("a pattern needs at least one spike and one silent step")
    reward_if_spike = np.where(wanted, MAX_REWARD / m, 0.0)
    reward_if_silent = np.where(wanted, 0.0, MAX_REWARD / (episode_length - m))
    return reward_if_spike, reward_if_silent


def random_legal_actions(action_mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One uniformly random legal action per row: the library's only random-action sampler.

    ``action_mask`` is bool [S, n + 1] (column a + 1 = action a, as in ``info["action_mask"]``);
    returns int64 [S] in -1..n-1, -1 (do nothing) for a row with nothing legal. Draws exactly
    ``rng.random(action_mask.shape)``, so a seed gives the same actions everywhere.
    """
    legal = np.asarray(action_mask, dtype=bool)
    scores = rng.random(legal.shape)  # [S, n + 1]
    scores[~legal] = -1.0
    return scores.argmax(axis=1).astype(np.int64) + DO_NOTHING  # [S]


@dataclass(frozen=True, eq=False)
class ContextTables:
    """What the environments read about contexts, stacked over S contexts.

    With hidden neurons the agent sees k < n neurons: ``observable`` maps its indices
    (observations and actions) to neuron indices; ``targets`` are neuron indices,
    ``observed_targets`` the agent's.
    """

    weights: np.ndarray
    """[S, n, n] float64 signed connectivity (times the synaptic scales of
    heterogeneous neurons), as the simulator takes it."""
    targets: np.ndarray
    """[S] int64 neuron index of the target."""
    patterns: np.ndarray
    """[S, N] int8, as observed."""
    reward_if_spike: np.ndarray
    """[S, N] float64."""
    reward_if_silent: np.ndarray
    """[S, N] float64."""
    legal: np.ndarray
    """[S, k + 1] bool action masks, index a + 1 for action a."""
    observed_targets: np.ndarray | None = None
    """[S] int64 index of the target among the observable neurons."""
    observable: np.ndarray | None = None
    """[S, k] int64 neuron index of each observed neuron; None: all n, in order."""
    neurons: np.ndarray | None = None
    """[S, 2, n] per-neuron kernel parameters (``neuron_parameters``) of heterogeneous
    neurons; None: the identical neurons of the parameters."""

    @classmethod
    def build(
        cls,
        contexts: Sequence[Context],
        allow_target_action: bool,
        params: NeuronParams | None = None,
    ) -> ContextTables:
        params = NeuronParams() if params is None else params
        targets = np.array([c.target for c in contexts], dtype=np.int64)
        observed_targets = np.array([c.observed_target for c in contexts], dtype=np.int64)
        patterns = np.stack([c.pattern for c in contexts]).astype(np.int8)
        k = contexts[0].n_observed
        legal = np.ones((len(contexts), k + 1), dtype=bool)
        if not allow_target_action:
            legal[np.arange(len(contexts)), observed_targets + 1] = False
        weights = np.ascontiguousarray(np.stack([c.weights for c in contexts]), dtype=np.float64)
        observable = neurons = None
        if contexts[0].hidden is not None:
            observable = np.stack([c.observable for c in contexts]).astype(np.int64)
        if contexts[0].heterogeneity is not None:
            weights *= np.stack([c.heterogeneity.synaptic_scale for c in contexts])
            neurons = neuron_parameters(
                params,
                np.stack([c.heterogeneity.thresholds_mV for c in contexts]),
                np.stack([c.heterogeneity.time_constants_ms for c in contexts]),
            )
        return cls(
            weights,
            targets,
            patterns,
            *step_rewards(patterns),
            legal,
            observed_targets,
            observable,
            neurons,
        )


@functools.lru_cache(maxsize=16)
def _cached_splits(
    n_train: int,
    n_test: int,
    n_neurons: int,
    episode_length: int,
    seed: int,
    params: NeuronParams,
    extensions: Extensions,
) -> tuple[ContextSet, ContextSet]:
    # Every environment of a SyncVectorEnv asks for the same sets; context sets are immutable.
    return make_splits(n_train, n_test, n_neurons, episode_length, seed, params, extensions)


@dataclass(frozen=True)
class GeneratedContexts:
    """The sets an environment generates when it is given no context set:
    ``make_splits(n_train, n_test, n_neurons, episode_length, seed, params, extensions)``,
    of which it plays the ``split``. Through ``gymnasium.make`` a dict of these fields:
    ``contexts={"n_train": 10, "n_test": 10, "seed": 3}``."""

    n_train: int = 100
    """Training contexts."""
    n_test: int = 100
    """Unseen test contexts (no topology shared with the training set)."""
    seed: int = 0
    """Seed of the generation."""

    def __post_init__(self) -> None:
        for name in ("n_train", "n_test"):
            check_size(getattr(self, name), f"contexts: {name}")
        check_seed(self.seed, "contexts: seed")

    @classmethod
    def coerce(cls, value: GeneratedContexts | Mapping[str, Any] | None) -> GeneratedContexts:
        """``value`` itself, the defaults for None, or one made from a dict of its fields
        (an unknown key is one ValueError line naming the fields)."""
        if isinstance(value, cls):
            return value
        if value is None:
            return cls()
        known = [field.name for field in fields(cls)]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ValueError(
                f"contexts: unknown key(s) {unknown}; generated sets take {', '.join(known)}"
            )
        return cls(**value)


class Setup(NamedTuple):
    """What an environment's constructor arguments resolve to (:func:`resolve_setup`)."""

    contexts: ContextSet
    params: NeuronParams
    extensions: Extensions
    tables: ContextTables
    effects: EnvironmentEffects


ContextsArgument = ContextSet | str | os.PathLike | GeneratedContexts | Mapping[str, Any] | None
"""What an environment's ``contexts`` argument may be: a set, a saved one, or how to
generate them (:class:`GeneratedContexts` or a dict of its fields; None: its defaults)."""


def resolve_setup(
    contexts: ContextsArgument,
    split: str,
    n_neurons: int | None,
    episode_length: int | None,
    params: NeuronParams | None,
    extensions: Extensions | Mapping[str, Any] | None,
    render_mode: str | None,
) -> Setup:
    """Check and resolve the constructor arguments that both environments take.

    Generated context sets are drawn with ``params`` and the context-level part of
    ``extensions``. The neuron parameters played are always the set's: ``params``
    only generates sets, and beside ``contexts`` it must be theirs
    (:meth:`ContextSet.check_params`).
    """
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be one of {RENDER_MODES} or None, got {render_mode!r}")
    requested = Extensions.coerce(extensions)
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if params is not None and not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams or None, got {type(params).__name__}")
    generated = contexts is None or isinstance(contexts, (GeneratedContexts, Mapping))
    if generated:
        generation = GeneratedContexts.coerce(contexts)
        n = DEFAULT_N_NEURONS if n_neurons is None else n_neurons
        length = DEFAULT_EPISODE_LENGTH if episode_length is None else episode_length
        if not is_int(n) or n < 2:
            raise ValueError(f"n_neurons must be an integer >= 2, got {n!r}")
        if not is_int(length) or length < 2:
            raise ValueError(f"episode_length must be an integer >= 2, got {length!r}")
        splits = _cached_splits(
            int(generation.n_train), int(generation.n_test), int(n), int(length),
            int(generation.seed),
            NeuronParams() if params is None else params, requested.context_part(),
        )  # fmt: skip
        context_set = splits[SPLITS.index(split)]
    elif isinstance(contexts, ContextSet):
        context_set = contexts
    elif isinstance(contexts, (str, os.PathLike)):
        context_set = ContextSet.load(contexts)
    else:
        raise TypeError(
            f"contexts must be a ContextSet, a path to a saved one, or how to generate them "
            f"(a dict of n_train, n_test, seed; None: the defaults); got {type(contexts).__name__}"
        )
    for name, given, actual in (
        ("n_neurons", n_neurons, context_set.n_neurons),
        ("episode_length", episode_length, context_set.episode_length),
    ):
        if given is not None and given != actual:
            raise ValueError(f"{name}={given!r} conflicts with the context set's {name} {actual}")
    if params is not None and not generated:
        context_set.check_params(
            params, "params=",
            "the environment plays the contexts' own params (params= generates contexts: "
            "leave it out, or generate contexts with these params)",
        )  # fmt: skip
    params = context_set.params
    effective = resolve_extensions(requested, context_set)
    tables = ContextTables.build(context_set, effective.allow_target_action, params)
    effects = EnvironmentEffects(effective, params, context_set.episode_length)
    return Setup(context_set, params, effective, tables, effects)


def resolve_extensions(
    extensions: Extensions | Mapping[str, Any] | None, context_set: ContextSet
) -> Extensions:
    """The environment's effective extensions: its own environment-level fields and the
    context set's context-level fields."""
    extensions = Extensions.coerce(extensions)
    own = extensions.context_part()
    if own != Extensions() and own != context_set.extensions:
        raise ValueError(
            f"context-level extensions {own.to_dict(only_changed=True)} differ from those of "
            f"the context set ({context_set.extensions.to_dict(only_changed=True)}): hidden and "
            "heterogeneous neurons belong to the contexts; generate the set with them "
            "(ContextSet.generate(..., extensions=...)) or leave them out here"
        )
    return replace(
        extensions, **{name: getattr(context_set.extensions, name) for name in CONTEXT_FIELDS}
    )


def check_context(context: Context, n_neurons: int, episode_length: int, n_observed=None) -> None:
    """Raise unless ``context`` is a Context of this environment's size and episode length
    (and number of observable neurons, when given)."""
    if not isinstance(context, Context):
        raise TypeError(f"expected a Context, got {type(context).__name__}")
    if (context.n_neurons, context.episode_length) != (n_neurons, episode_length):
        raise ValueError(
            f"the context has {context.n_neurons} neurons and episode length "
            f"{context.episode_length}; this environment has {n_neurons} and {episode_length}"
        )
    if n_observed is not None and context.n_observed != n_observed:
        raise ValueError(
            f"the context has {context.n_observed} observable neurons; this environment "
            f"observes {n_observed}"
        )


def check_context_index(index: Any, size: int) -> int:
    """``index`` as an int, or a ValueError unless it indexes a set of ``size`` contexts."""
    if not is_int(index) or not 0 <= index < size:
        raise ValueError(f"context index must be an integer in 0..{size - 1}, got {index!r}")
    return int(index)


def as_action(action: Any) -> int:
    """An action as a Python int: ints, NumPy integer scalars and 0-d integer arrays."""
    from spikectl.envs.env_arguments import short_repr

    if isinstance(action, (bool, np.bool_)):
        raise ValueError(f"action must be an integer, got the boolean {action!r}")
    try:
        return operator.index(action)
    except TypeError:
        raise ValueError(f"action must be an integer, got {short_repr(action)}") from None


def observation_space(
    n_neurons: int,
    episode_length: int,
    latency_steps: int = 0,
    spikes_only: bool = False,
    recorded: bool = False,
) -> spaces.Dict:
    """The observation space of one environment (docs/environment.md); the connectivity is
    not in it. With loop latency (an extension) it has ``actions_in_flight`` too; with
    spikes-only sensing ``spikes`` in place of ``voltage``; with a recorded subset
    (``recorded``) the int8 mask ``recorded``."""
    entries = {
        sensed_key(spikes_only): sensed_space(n_neurons, spikes_only),
        "target": spaces.Discrete(n_neurons),
        "pattern": spaces.MultiBinary(episode_length),
        "step": spaces.Discrete(episode_length + 1),
        "last_action": spaces.Discrete(n_neurons + 1, start=DO_NOTHING),
    }
    if latency_steps:
        entries[IN_FLIGHT_KEY] = in_flight_space(n_neurons + 1, latency_steps)
    if recorded:
        entries[RECORDED_KEY] = spaces.MultiBinary(n_neurons)
    return spaces.Dict(entries)


class LegalActionSpace(spaces.Discrete):
    """``Discrete(n + 1, start=-1)`` whose unmasked ``sample()`` draws only legal actions.

    ``contains`` is the whole range -1..n-1; ``legal_mask`` (int8 [n + 1], set by the
    environment at every reset) restricts what ``sample()`` draws when no mask is given,
    so that random agents and Gymnasium's ``check_env`` never pick the target neuron.
    """

    def __init__(self, n_neurons: int, seed: int | None = None) -> None:
        super().__init__(n_neurons + 1, seed=seed, start=DO_NOTHING)
        self.legal_mask = np.ones(n_neurons + 1, dtype=np.int8)

    def sample(
        self, mask: np.ndarray | None = None, probability: np.ndarray | None = None
    ) -> np.int64:
        if mask is not None or probability is not None:
            return super().sample(mask=mask, probability=probability)
        return random_legal_actions(self.legal_mask[None], self.np_random)[0]


class LegalActionBatchSpace(spaces.MultiDiscrete):
    """The batched action space; its unmasked ``sample()`` draws only legal actions.

    Equal to ``batch_space(Discrete(n + 1, start=-1), num_envs)``. ``legal`` (bool
    [num_envs, n + 1]) is the environment's current action mask.
    """

    def __init__(self, num_envs: int, n_neurons: int, seed: int | None = None) -> None:
        super().__init__(
            np.full(num_envs, n_neurons + 1), seed=seed, start=np.full(num_envs, DO_NOTHING)
        )
        self.legal = np.ones((num_envs, n_neurons + 1), dtype=bool)

    def sample(self, mask: tuple | None = None, probability: tuple | None = None) -> np.ndarray:
        if mask is not None or probability is not None:
            return super().sample(mask=mask, probability=probability)
        return random_legal_actions(self.legal, self.np_random).astype(self.dtype)
