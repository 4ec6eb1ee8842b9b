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

from spikectl.config_errors import MissingExtraError
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers.sb3_spaces import (
    DO_NOTHING,
    check_illegal_action,
    observation_for,
    to_env_action,
)

if TYPE_CHECKING:
    from spikectl.wrappers.sb3_vec_adapter import SB3VecEnv


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
        check_illegal_action(illegal_action)
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
        """The seed of the wrapped environment's generator."""
        return self.env.unwrapped.np_random_seed

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray | dict[str, Any], dict[str, Any]]:
        """Reset the wrapped environment; the observation in SB3's conventions."""
        observation, info = self.env.reset(seed=seed, options=options)
        self._mask = info["action_mask"].copy()
        return self.observation_codec(observation), info

    def step(
        self, action: Any
    ) -> tuple[np.ndarray | dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Step with a zero-based action (0 does nothing, j + 1 stimulates neuron j)."""
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
        """The wrapped environment's render."""
        return self.env.render()

    def close(self) -> None:
        """Close the wrapped environment."""
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
        raise MissingExtraError(
            f"sb3_vec_env needs Stable-Baselines3 ({error}); install it with "
            'pip install "spikectl[sb3]"'
        ) from None
    return SB3VecEnv(env, flatten=flatten, illegal_action=illegal_action)


__all__ = ["SB3CompatibleEnv", "make_sb3_compatible", "sb3_compatible", "sb3_vec_env"]
