"""The Gymnasium environment of SPEC section 3: make one neuron spike a target pattern.

Besides :class:`NeuronControlEnv` this module holds what the vector environment
shares with it: resolving the ``contexts`` argument to a :class:`ContextSet`,
the per-context lookup tables (:class:`ContextTables`), the reward formula
(:func:`step_rewards`) and the action checks.
"""

from __future__ import annotations

import functools
import operator
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from spikectl import render as rendering
from spikectl.contexts import Context, ContextSet, make_splits
from spikectl.params import NeuronParams
from spikectl.simulator import DO_NOTHING, SimulatorState, advance

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
    R_max / (N - m) for a wanted silence, 0 otherwise (SPEC 3).
    """
    wanted = np.asarray(patterns).astype(bool)
    episode_length = wanted.shape[-1]
    m = wanted.sum(axis=-1, keepdims=True)
    if np.any(m == 0) or np.any(m == episode_length):
        raise ValueError("a pattern needs at least one spike and one silent step")
    reward_if_spike = np.where(wanted, MAX_REWARD / m, 0.0)
    reward_if_silent = np.where(wanted, 0.0, MAX_REWARD / (episode_length - m))
    return reward_if_spike, reward_if_silent


@dataclass(frozen=True, eq=False)
class ContextTables:
    """What the environments read about contexts, stacked over S contexts."""

    weights: np.ndarray
    """[S, n, n] float64 signed connectivity, as the simulator takes it."""
    targets: np.ndarray
    """[S] int64."""
    patterns: np.ndarray
    """[S, N] int8, as observed."""
    reward_if_spike: np.ndarray
    """[S, N] float64."""
    reward_if_silent: np.ndarray
    """[S, N] float64."""
    legal: np.ndarray
    """[S, n + 1] bool action masks, index a + 1 for action a."""

    @classmethod
    def build(cls, contexts: Sequence[Context], allow_target_action: bool) -> ContextTables:
        targets = np.array([c.target for c in contexts], dtype=np.int64)
        patterns = np.stack([c.pattern for c in contexts]).astype(np.int8)
        n = contexts[0].n_neurons
        legal = np.ones((len(contexts), n + 1), dtype=bool)
        if not allow_target_action:
            legal[np.arange(len(contexts)), targets + 1] = False
        return cls(
            np.ascontiguousarray(np.stack([c.weights for c in contexts]), dtype=np.float64),
            targets,
            patterns,
            *step_rewards(patterns),
            legal,
        )


@functools.lru_cache(maxsize=16)
def _cached_splits(
    n_train: int, n_test: int, n_neurons: int, episode_length: int, seed: int, params: NeuronParams
) -> tuple[ContextSet, ContextSet]:
    # Every environment of a SyncVectorEnv asks for the same sets; context sets are immutable.
    return make_splits(n_train, n_test, n_neurons, episode_length, seed, params)


def resolve_contexts(
    contexts: ContextSet | str | os.PathLike | None,
    split: str,
    n_train: int,
    n_test: int,
    context_seed: int,
    n_neurons: int | None,
    episode_length: int | None,
    params: NeuronParams | None,
) -> tuple[ContextSet, NeuronParams]:
    """The environment's context set and model parameters, from its constructor arguments."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if params is not None and not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams or None, got {type(params).__name__}")
    if contexts is None:
        for name, value in (("n_train", n_train), ("n_test", n_test)):
            if not is_int(value) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if not is_int(context_seed) or context_seed < 0:
            raise ValueError(f"context_seed must be a non-negative integer, got {context_seed!r}")
        n = DEFAULT_N_NEURONS if n_neurons is None else n_neurons
        length = DEFAULT_EPISODE_LENGTH if episode_length is None else episode_length
        if not is_int(n) or n < 2:
            raise ValueError(f"n_neurons must be an integer >= 2, got {n!r}")
        if not is_int(length) or length < 2:
            raise ValueError(f"episode_length must be an integer >= 2, got {length!r}")
        splits = _cached_splits(
            int(n_train), int(n_test), int(n), int(length), int(context_seed),
            NeuronParams() if params is None else params,
        )  # fmt: skip
        context_set = splits[SPLITS.index(split)]
    elif isinstance(contexts, ContextSet):
        context_set = contexts
    elif isinstance(contexts, (str, os.PathLike)):
        context_set = ContextSet.load(contexts)
    else:
        raise TypeError(
            f"contexts must be a ContextSet, a path to a saved one, or None; "
            f"got {type(contexts).__name__}"
        )
    for name, given, actual in (
        ("n_neurons", n_neurons, context_set.n_neurons),
        ("episode_length", episode_length, context_set.episode_length),
    ):
        if given is not None and given != actual:
            raise ValueError(f"{name}={given!r} conflicts with the context set's {name} {actual}")
    return context_set, context_set.params if params is None else params


def check_context(context: Context, n_neurons: int, episode_length: int) -> None:
    """Raise unless ``context`` is a Context of this environment's size and episode length."""
    if not isinstance(context, Context):
        raise TypeError(f"expected a Context, got {type(context).__name__}")
    if (context.n_neurons, context.episode_length) != (n_neurons, episode_length):
        raise ValueError(
            f"the context has {context.n_neurons} neurons and episode length "
            f"{context.episode_length}; this environment has {n_neurons} and {episode_length}"
        )


def check_context_index(index: Any, size: int) -> int:
    """``index`` as an int, or a ValueError unless it indexes a set of ``size`` contexts."""
    if not is_int(index) or not 0 <= index < size:
        raise ValueError(f"context index must be an integer in 0..{size - 1}, got {index!r}")
    return int(index)


def as_action(action: Any) -> int:
    """An action as a Python int: ints, NumPy integer scalars and 0-d integer arrays."""
    if isinstance(action, (bool, np.bool_)):
        raise ValueError(f"action must be an integer, got the boolean {action!r}")
    try:
        return operator.index(action)
    except TypeError:
        raise ValueError(f"action must be an integer, got {action!r}") from None


def observation_space(n_neurons: int, episode_length: int) -> spaces.Dict:
    """The observation space of one environment (SPEC 3); the connectivity is not in it."""
    return spaces.Dict(
        {
            "voltage": spaces.Box(-np.inf, np.inf, (n_neurons,), np.float32),
            "target": spaces.Discrete(n_neurons),
            "pattern": spaces.MultiBinary(episode_length),
            "step": spaces.Discrete(episode_length + 1),
            "last_action": spaces.Discrete(n_neurons + 1, start=DO_NOTHING),
        }
    )


def is_int(value: Any) -> bool:
    """True for Python and NumPy integers, False for booleans (which Python calls ints)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


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
        if mask is None and probability is None:
            mask = self.legal_mask
        return super().sample(mask=mask, probability=probability)


class NeuronControlEnv(gym.Env[dict[str, Any], int]):
    """
    ## Description

    Closed-loop control of a simulated network of leaky integrate-and-fire neurons
    with short-term synaptic depression (SPEC 1). In each episode a *context* fixes the
    hidden signed connectivity, a target neuron and a binary target pattern of N steps;
    the agent stimulates one (non-target) neuron per step, or none, so that the target
    spikes exactly when the pattern says. Every context carries a witness action sequence
    that reproduces its pattern, so the best return is always 1.

    ## Action Space

    `Discrete(n + 1, start=-1)`: -1 does nothing, j in 0..n-1 stimulates neuron j for one
    step (+40 mV; a refractory neuron ignores it). The target neuron is illegal unless
    `allow_target_action=True`; an illegal, out-of-range or non-integer action raises
    `ValueError`. `info["action_mask"]` marks the legal actions; `action_space.sample()`
    draws only legal ones.

    ## Observation Space

    A `Dict`; the connectivity is never observed.

    | key           | space                           | meaning                               |
    |---------------|---------------------------------|---------------------------------------|
    | `voltage`     | `Box(-inf, inf, (n,), float32)` | membrane potentials in mV (see below) |
    | `target`      | `Discrete(n)`                   | the neuron to control                 |
    | `pattern`     | `MultiBinary(N)` (int8)         | steps at which the target must spike  |
    | `step`        | `Discrete(N + 1)`               | index of the next step: 0 after reset |
    | `last_action` | `Discrete(n + 1, start=-1)`     | the previous action, -1 after reset   |

    Potentials are observed after integration and before reset, so a spike shows as
    >= -50 mV; after reset all are at rest (-70 mV).

    ## Rewards

    With m spikes in the pattern, step t earns R_max/m if the target spikes and
    pattern[t] = 1, R_max/(N - m) if it is silent and pattern[t] = 0, else 0; R_max = 0.5.
    An episode's return lies in [0, 1]; doing nothing scores 0.5, the witness 1.

    ## Starting State

    Every neuron at rest (-70 mV) with no history; the context is drawn uniformly
    from the configured set with `self.np_random`, or chosen by `reset` options.

    ## Episode End

    Termination (never truncation) after step N - 1. Stepping again before `reset`
    raises `gymnasium.error.ResetNeeded`.

    ## Arguments

    | argument              | default   | meaning                                          |
    |-----------------------|-----------|--------------------------------------------------|
    | `n_neurons`           | `None`    | n; None: the context set's, else 8               |
    | `episode_length`      | `None`    | N; None: the context set's, else 60              |
    | `contexts`            | `None`    | a `ContextSet`, a path to a saved one, or None   |
    | `split`               | `"train"` | generated set to play: `"train"` or `"test"`     |
    | `n_train`, `n_test`   | 100, 100  | sizes of the generated sets (`make_splits`)      |
    | `context_seed`        | 0         | seed of the generated sets                       |
    | `params`              | `None`    | `NeuronParams`; None: the context set's          |
    | `allow_target_action` | `False`   | make stimulating the target legal (SPEC 6)       |
    | `render_mode`         | `None`    | `"ansi"` or `"rgb_array"`                        |

    With `contexts=None` the sets are generated by `make_splits(n_train, n_test, n_neurons,
    episode_length, context_seed, params)` (cached, so many environments share them);
    with `contexts` given, `split`, `n_train`, `n_test` and `context_seed` are unused and
    an explicit `n_neurons` or `episode_length` must agree with the set.

    `reset(options={"context": c})` plays context `c`: an index into the set or a
    `Context` of the same size. `info` holds `action_mask` (bool [n + 1], index a + 1
    for action a), `context_index` (None for a passed `Context`) and, after a step,
    `spikes` (bool [n]) and `target_spiked`.

    ```python
    >>> import gymnasium as gym
    >>> import spikectl
    >>> env = gym.make("spikectl/NeuronControl-v0", n_train=10, n_test=10)
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(-1)

    ```

    ## Version History
    * v0: Initial version (SPEC sections 1-3).
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(
        self,
        n_neurons: int | None = None,
        episode_length: int | None = None,
        contexts: ContextSet | str | os.PathLike | None = None,
        split: str = "train",
        n_train: int = 100,
        n_test: int = 100,
        context_seed: int = 0,
        params: NeuronParams | None = None,
        allow_target_action: bool = False,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be one of {RENDER_MODES} or None, got {render_mode!r}"
            )
        if not isinstance(allow_target_action, (bool, np.bool_)):
            raise TypeError(f"allow_target_action must be a bool, got {allow_target_action!r}")
        self.contexts, self.params = resolve_contexts(
            contexts, split, n_train, n_test, context_seed, n_neurons, episode_length, params
        )
        self.n_neurons = n = self.contexts.n_neurons
        self.episode_length = length = self.contexts.episode_length
        self.allow_target_action = bool(allow_target_action)
        self.render_mode = render_mode
        self._tables = ContextTables.build(self.contexts, self.allow_target_action)

        self.action_space = LegalActionSpace(n)
        self.observation_space = observation_space(n, length)
        # Episode history, written by the simulator in place through per-step views.
        self._action_history = np.full((1, length), DO_NOTHING, dtype=np.int64)
        self._voltage_history = np.zeros((length, n), dtype=np.float64)
        self._spike_history = np.zeros((length, n), dtype=bool)
        self._make_step_views()
        self._state: SimulatorState | None = None
        self._next_step = length  # no episode until reset
        self._context_index: int | None = None

    def _make_step_views(self) -> None:
        self._step_views = [
            (
                self._action_history[:, t : t + 1],
                self._voltage_history[None, t : t + 1],
                self._spike_history[None, t : t + 1],
            )
            for t in range(self.episode_length)
        ]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        context = None if options is None else _context_option(options)
        if isinstance(context, Context):
            check_context(context, self.n_neurons, self.episode_length)
            tables = ContextTables.build([context], self.allow_target_action)
            row, self._context_index = 0, None
        else:
            if context is None:
                context = self.np_random.integers(len(self.contexts))
            row = self._context_index = check_context_index(context, len(self.contexts))
            tables = self._tables
        self._weights = tables.weights[row : row + 1]
        self._target = int(tables.targets[row])
        self._pattern = tables.patterns[row]
        self._reward_if_spike = tables.reward_if_spike[row].tolist()
        self._reward_if_silent = tables.reward_if_silent[row].tolist()
        self._legal = tables.legal[row]
        self._legal_list = self._legal.tolist()
        self.action_space.legal_mask = self._legal.astype(np.int8)
        self._state = SimulatorState.at_rest(1, self.n_neurons, self.params)
        self._action_history.fill(DO_NOTHING)
        self._spike_history.fill(False)
        self._next_step = 0
        observation = {
            "voltage": np.full(self.n_neurons, self.params.v_rest_mV, dtype=np.float32),
            "target": self._target,
            "pattern": self._pattern.copy(),
            "step": 0,
            "last_action": DO_NOTHING,
        }
        info = {"action_mask": self._legal.copy(), "context_index": self._context_index}
        return observation, info

    def step(self, action: int) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        t = self._next_step
        if t >= self.episode_length:
            raise ResetNeeded(
                "call reset() before step()"
                if self._state is None
                else "the episode has terminated: call reset() before step()"
            )
        if type(action) is not int:
            action = as_action(action)
        if action < DO_NOTHING or action >= self.n_neurons or not self._legal_list[action + 1]:
            raise ValueError(self._illegal_action_message(action))
        actions, voltage, spikes = self._step_views[t]
        actions[0, 0] = action
        advance(self._state, self._weights, actions, self.params, voltage, spikes)
        spikes = self._spike_history[t]
        target_spiked = bool(spikes[self._target])
        reward = self._reward_if_spike[t] if target_spiked else self._reward_if_silent[t]
        self._next_step = t + 1
        observation = {
            "voltage": self._voltage_history[t].astype(np.float32),
            "target": self._target,
            "pattern": self._pattern.copy(),
            "step": t + 1,
            "last_action": action,
        }
        info = {
            "action_mask": self._legal.copy(),
            "context_index": self._context_index,
            "spikes": spikes.copy(),
            "target_spiked": target_spiked,
        }
        return observation, reward, t + 1 == self.episode_length, False, info

    def _illegal_action_message(self, action: int) -> str:
        if DO_NOTHING <= action < self.n_neurons:
            return (
                f"action {action} stimulates the target neuron {self._target}, which is not a "
                f"legal action (pass allow_target_action=True to allow it)"
            )
        return (
            f"action {action} is out of range: actions are -1 (do nothing) or a neuron in "
            f"0..{self.n_neurons - 1} other than the target {self._target}"
        )

    def render(self) -> str | np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='ansi' or "
                "'rgb_array' to the constructor (or to gymnasium.make)"
            )
            return None
        if self._state is None:
            raise ResetNeeded("call reset() before render()")
        draw = rendering.render_ansi if self.render_mode == "ansi" else rendering.render_rgb
        return draw(
            self._pattern,
            self._spike_history[:, self._target],
            self._action_history[0],
            self._spike_history,
            self._target,
            self._next_step,
        )

    def __getstate__(self) -> dict[str, Any]:
        # The step views alias the history arrays; pickling would turn them into copies.
        state = self.__dict__.copy()
        del state["_step_views"]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._make_step_views()


def _context_option(options: dict[str, Any]) -> Any:
    unknown = set(options) - {"context"}
    if unknown:
        raise ValueError(f"unknown reset option(s) {sorted(unknown)}; the only option is 'context'")
    return options.get("context")
