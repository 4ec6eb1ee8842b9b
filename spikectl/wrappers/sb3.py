"""The environment in the conventions of other RL libraries (Stable-Baselines3, sb3-contrib).

The base environments keep the paper's conventions (docs/environment.md): actions
-1..n-1 with -1 = do nothing, an illegal action raises, the voltage is unbounded and
the observation is a ``Dict`` with a ``Discrete(start=-1)`` entry. Libraries such as
Stable-Baselines3 assume zero-based spaces, bounded boxes, legal sampling or
``action_masks()``. :func:`sb3_compatible` wraps one environment and
:func:`sb3_vec_env` the batched one for them; neither changes the dynamics or the
rewards, only how actions and observations are written (docs/ecosystem.md).

Actions: ``Discrete(k + 1)``; 0 does nothing and a >= 1 stimulates (observable) neuron
a - 1, so action a is the base environment's a - 1 and ``action_masks()[a]`` is the
base ``info["action_mask"][a]`` unchanged. An illegal action (the target neuron)
does nothing by default (``illegal_action="do_nothing"``; ``info["illegal_action"]``
says so) or raises (``"raise"``, the base environment's behaviour).

Observations: the base ``Dict`` with ``last_action`` zero-based and the voltage clipped
to the finite bounds of :func:`voltage_bounds_mV` (``flatten=False``), or by default one
float32 vector (``flatten=True``, layout in :class:`SB3Observation`) that every SB3
policy, ``VecNormalize`` and ``VecFrameStack`` accept.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.params import NEVER_RELEASES, NeuronParams

if TYPE_CHECKING:
    from spikectl.wrappers.sb3_vec_adapter import SB3VecEnv

DO_NOTHING = 0
"""The zero-based action that stimulates no neuron (the base environment's -1)."""
ILLEGAL_ACTIONS = ("do_nothing", "raise")
"""What an illegal action (stimulating the target) does: nothing, or raise ValueError."""


def to_env_action(action: Any) -> Any:
    """Zero-based action(s) a -> the base environment's a - 1 (0 -> -1, do nothing)."""
    return action - 1


def from_env_action(action: Any) -> Any:
    """The base environment's action(s) a -> zero-based a + 1 (-1 -> 0, do nothing)."""
    return action + 1


def voltage_bounds_mV(
    params: NeuronParams, n_neurons: int, stochastic_release: bool = False
) -> tuple[float, float]:
    """Bounds (low, high) in mV on every potential a network of ``n_neurons`` can show.

    Per step a neuron at V moves to V - (V - V_rest) dt/(R C) + drive, where the drive
    is the stimulus (dt w_e / C) plus dt w_in / C per released presynaptic neuron; any
    of the n neurons (itself included, for hand-made contexts) may be presynaptic, with
    weight -1, 0 or +1.

    - high: a neuron that has not spiked is below V_th, and leaking towards rest only
      lowers it, so V < V_th + dt (w_e + n w_in) / C.
    - low: a neuron releases at most once every K = ``min_release_interval_steps``
      steps (K = 1 with stochastic release), so n inhibitory partners, each kicking
      as often as it can, leave at most sum_j n (dt w_in / C) (1 - dt/(R C))^(K j)
      below rest: V >= V_rest - n (dt w_in / C) / (1 - (1 - dt/(R C))^K).

    With the defaults and n = 8: (-777.3, 150.0). They hold exactly for the paper's
    model; heterogeneous neurons, background input and measurement noise
    (docs/extensions.md) can go beyond them, and the wrappers clip.
    """
    interval = 1 if stochastic_release else params.min_release_interval_steps
    synaptic_step_mV = params.dt_ms * params.synaptic_current_pA / params.capacitance_pF
    if interval == NEVER_RELEASES or (stochastic_release and params.release_scale == 0):
        synaptic_step_mV = 0.0
        interval = 1
    stimulus_step_mV = params.dt_ms * params.stimulus_current_pA / params.capacitance_pF
    leak_per_step = params.dt_ms / params.membrane_time_constant_ms
    high = params.v_threshold_mV + stimulus_step_mV + n_neurons * synaptic_step_mV
    low = params.v_rest_mV - n_neurons * synaptic_step_mV / (
        1.0 - (1.0 - leak_per_step) ** interval
    )
    return low, high


def _float32_outward(low: float, high: float) -> tuple[np.float32, np.float32]:
    """float32 bounds that contain [low, high] (a cast alone may round inwards)."""
    low32, high32 = np.float32(low), np.float32(high)
    if low32 > low:
        low32 = np.nextafter(low32, np.float32(-np.inf))
    if high32 < high:
        high32 = np.nextafter(high32, np.float32(np.inf))
    return low32, high32


class SB3Observation:
    """The wrappers' observation space and the map from the base observation to it.

    Works on one observation or on a batch (leading axis, as the vector environment
    gives them). With ``flatten=False`` the base ``Dict`` with ``last_action`` in
    0..k (0: none, a: neuron a - 1) and the voltage in mV clipped to
    :func:`voltage_bounds_mV`. With ``flatten=True`` one float32 vector of
    3k + 3N + 2 entries:

    | slice          | entries                                                   |
    |----------------|-----------------------------------------------------------|
    | ``[0, k)``     | voltage as (V - V_rest) / (V_th - V_rest): 0 at rest, 1 at |
    |                | threshold; bounds scaled alike (-35.4, 11 for n = 8)       |
    | ``[k, 2k)``    | target, one-hot                                           |
    | ``[2k, 3k+1)`` | last action, one-hot over 0..k                            |
    | next N + 1     | step t, one-hot over 0..N                                 |
    | next N         | pattern                                                   |
    | next N         | pattern ahead: pattern[t + j], -1 past the end            |

    The pattern ahead repeats what pattern and step say, aligned with the current step,
    so that a policy without memory or attention can read the next wanted spikes.
    """

    def __init__(
        self,
        n_observed: int,
        n_neurons: int,
        episode_length: int,
        params: NeuronParams,
        stochastic_release: bool = False,
        flatten: bool = True,
    ) -> None:
        self.k = k = n_observed
        self.N = length = episode_length
        self.flatten = flatten
        self.v_rest_mV, self.v_threshold_mV = params.v_rest_mV, params.v_threshold_mV
        low, high = _float32_outward(*voltage_bounds_mV(params, n_neurons, stochastic_release))
        self.voltage_low_mV, self.voltage_high_mV = low, high
        self._ahead = np.arange(length)  # [N]
        if not flatten:
            self.space = spaces.Dict(
                {
                    "voltage": spaces.Box(low, high, (k,), np.float32),
                    "target": spaces.Discrete(k),
                    "pattern": spaces.MultiBinary(length),
                    "step": spaces.Discrete(length + 1),
                    "last_action": spaces.Discrete(k + 1),
                }
            )
            return
        size = 3 * k + 3 * length + 2
        lows = np.zeros(size, dtype=np.float32)
        highs = np.ones(size, dtype=np.float32)
        lows[:k], highs[:k] = _float32_outward(self._scaled(low), self._scaled(high))
        lows[-length:] = -1.0
        self.space = spaces.Box(lows, highs, (size,), np.float32)

    def _scaled(self, voltage_mV: Any) -> Any:
        return (voltage_mV - self.v_rest_mV) / (self.v_threshold_mV - self.v_rest_mV)

    def __call__(self, observation: dict[str, Any]) -> np.ndarray | dict[str, Any]:
        """The observation (or batch) of the base environment in this space."""
        voltage = np.clip(
            np.asarray(observation["voltage"], dtype=np.float32),
            self.voltage_low_mV,
            self.voltage_high_mV,
        )
        last_action = from_env_action(np.asarray(observation["last_action"], dtype=np.int64))
        if not self.flatten:
            batched = voltage.ndim == 2
            return {
                "voltage": voltage,
                "target": np.asarray(observation["target"], dtype=np.int64)
                if batched
                else int(observation["target"]),
                "pattern": np.asarray(observation["pattern"], dtype=np.int8),
                "step": np.asarray(observation["step"], dtype=np.int64)
                if batched
                else int(observation["step"]),
                "last_action": last_action if batched else int(last_action),
            }
        k, length = self.k, self.N
        target = np.asarray(observation["target"])
        step = np.asarray(observation["step"])
        pattern = np.asarray(observation["pattern"], dtype=np.float32)  # [..., N]
        index = step[..., None] + self._ahead  # [..., N]
        ahead = np.where(
            index < length,
            np.take_along_axis(pattern, np.minimum(index, length - 1), axis=-1),
            np.float32(-1.0),
        )  # [..., N]
        scaled = self._scaled(voltage)
        low, high = self.space.low[0], self.space.high[0]
        return np.concatenate(
            [
                np.clip(scaled, low, high).astype(np.float32),  # [..., k]
                _one_hot(target, k),  # [..., k]
                _one_hot(last_action, k + 1),  # [..., k+1]
                _one_hot(step, length + 1),  # [..., N+1]
                pattern,  # [..., N]
                ahead.astype(np.float32),  # [..., N]
            ],
            axis=-1,
        )


def _one_hot(index: np.ndarray, size: int) -> np.ndarray:
    return np.eye(size, dtype=np.float32)[index]  # [..., size]


def _check_illegal_action(illegal_action: str) -> None:
    if illegal_action not in ILLEGAL_ACTIONS:
        raise ValueError(f"illegal_action must be one of {ILLEGAL_ACTIONS}, got {illegal_action!r}")


def observation_for(env: Any, flatten: bool) -> SB3Observation:
    """The :class:`SB3Observation` of a (single or vector) spikectl environment."""
    return SB3Observation(
        env.n_observed,
        env.n_neurons,
        env.episode_length,
        env.params,
        env.extensions.stochastic_release,
        flatten,
    )


class SB3CompatibleEnv(gym.Env):
    """A spikectl environment with zero-based actions, masks and bounded observations.

    See the module docstring and docs/ecosystem.md. Dynamics, rewards, seeding and
    episode ends are the base environment's; ``action_masks()`` (bool [k + 1]) is the
    mask of the current state, as sb3-contrib's ``MaskablePPO`` reads it.

    It holds the base environment (``self.env``) rather than being a ``gym.Wrapper``:
    Gymnasium's ``check_env`` warns about any wrapper, and this is a new interface to
    the environment, not a layer over the same one. Its ``np_random`` is the base
    environment's, so there is one generator, seeded by ``reset(seed=...)``.
    """

    def __init__(
        self, env: gym.Env, *, flatten: bool = True, illegal_action: str = "do_nothing"
    ) -> None:
        if not isinstance(env.unwrapped, NeuronControlEnv):
            raise TypeError(
                f"sb3_compatible wraps a spikectl NeuronControlEnv (or gymnasium.make of a "
                f"spikectl id), got {type(env.unwrapped).__name__}"
            )
        _check_illegal_action(illegal_action)
        self.env = env
        self.illegal_action = illegal_action
        self.metadata = env.metadata
        self.render_mode = env.render_mode
        self.observation_codec = observation_for(env.unwrapped, flatten)
        self.observation_space = self.observation_codec.space
        self.action_space = spaces.Discrete(env.unwrapped.n_observed + 1)
        self._mask = np.zeros(self.action_space.n, dtype=bool)
        if env.spec is not None:  # gymnasium.make(self.spec) rebuilds this environment
            self.spec = EnvSpec(
                env.spec.id,
                entry_point=make_sb3_compatible,
                nondeterministic=env.spec.nondeterministic,
                kwargs={
                    **env.spec.kwargs,
                    "env_id": env.spec.id,
                    "flatten": flatten,
                    "illegal_action": illegal_action,
                },
            )

    @property
    def _np_random(self) -> np.random.Generator | None:
        return self.env.unwrapped._np_random

    @_np_random.setter
    def _np_random(self, value: np.random.Generator | None) -> None:
        self.env.unwrapped._np_random = value

    @property
    def np_random_seed(self) -> int:
        return self.env.unwrapped.np_random_seed

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray | dict[str, Any], dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self._mask = info["action_mask"].copy()
        return self.observation_codec(observation), info

    def step(
        self, action: Any
    ) -> tuple[np.ndarray | dict[str, Any], float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(
                f"action {action!r} is not in {self.action_space}: 0 does nothing, "
                f"a in 1..{self.action_space.n - 1} stimulates neuron a - 1"
            )
        action = int(action)
        illegal = not self._mask[action]
        if illegal and self.illegal_action == "do_nothing":
            action = DO_NOTHING
        observation, reward, terminated, truncated, info = self.env.step(to_env_action(action))
        self._mask = info["action_mask"].copy()
        info["illegal_action"] = illegal
        return self.observation_codec(observation), reward, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """Legal actions now: bool [k + 1], entry a for zero-based action a."""
        return self._mask.copy()

    def render(self) -> str | np.ndarray | None:
        return self.env.render()

    def close(self) -> None:
        self.env.close()


def sb3_compatible(
    env: gym.Env, *, flatten: bool = True, illegal_action: str = "do_nothing"
) -> SB3CompatibleEnv:
    """``env`` (a ``NeuronControlEnv`` or ``gymnasium.make`` of a spikectl id) wrapped for
    Stable-Baselines3 and sb3-contrib: see :class:`SB3CompatibleEnv` and docs/ecosystem.md.

    ``flatten``: one float32 vector (default) or a ``Dict`` (for ``MultiInputPolicy``).
    ``illegal_action``: ``"do_nothing"`` (default) or ``"raise"``.
    """
    return SB3CompatibleEnv(env, flatten=flatten, illegal_action=illegal_action)


def make_sb3_compatible(
    env_id: str, *, flatten: bool = True, illegal_action: str = "do_nothing", **kwargs: Any
) -> SB3CompatibleEnv:
    """``sb3_compatible(gymnasium.make(env_id, **kwargs), ...)``: the entry point of the
    wrapped environment's ``spec``."""
    return sb3_compatible(
        gym.make(env_id, **kwargs), flatten=flatten, illegal_action=illegal_action
    )


def sb3_vec_env(
    env: NeuronControlVectorEnv | gym.vector.VectorEnv,
    *,
    flatten: bool = True,
    illegal_action: str = "do_nothing",
) -> SB3VecEnv:
    """The batched ``NeuronControlVectorEnv`` (or ``gymnasium.make_vec`` of a spikectl id) as
    a Stable-Baselines3 ``VecEnv``, with the spaces of :func:`sb3_compatible` and per-env
    ``action_masks`` for ``MaskablePPO``; needs ``pip install "spikectl[sb3]"``."""
    try:
        from spikectl.wrappers.sb3_vec_adapter import SB3VecEnv
    except ImportError as error:
        raise ImportError(
            f"sb3_vec_env needs Stable-Baselines3 ({error}); install it with "
            'pip install "spikectl[sb3]"'
        ) from None
    return SB3VecEnv(env, flatten=flatten, illegal_action=illegal_action)


__all__ = [
    "DO_NOTHING",
    "ILLEGAL_ACTIONS",
    "SB3CompatibleEnv",
    "SB3Observation",
    "from_env_action",
    "make_sb3_compatible",
    "observation_for",
    "sb3_compatible",
    "sb3_vec_env",
    "to_env_action",
    "voltage_bounds_mV",
]
