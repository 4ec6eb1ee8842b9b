"""The batched environment as a Stable-Baselines3 ``VecEnv`` (needs the ``[sb3]`` extra).

Build it with :func:`spikectl.wrappers.sb3_vec_env`. It steps every environment of a
:class:`~spikectl.envs.vector_env.NeuronControlVectorEnv` in one call, in the spaces of
:func:`spikectl.wrappers.sb3_compatible`, and follows SB3's conventions: an environment
that ends is reset within the same ``step`` (its last observation is in
``info["terminal_observation"]``), seeds and options given with ``seed()`` /
``set_options()`` apply at the next ``reset()``, and ``env_method("action_masks")`` gives
one mask per environment, which is how sb3-contrib's ``MaskablePPO`` finds them.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices

from spikectl.envs.env_arguments import bad_actions_message, bad_shape_message
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers.conventions import (
    check_illegal_action,
    legal_or_nothing,
    observation_for,
    to_env_action,
)
from spikectl.wrappers.flat_vector_env import FlatNeuronControlVectorEnv


class SB3VecEnv(VecEnv):
    """``NeuronControlVectorEnv`` behind SB3's ``VecEnv`` interface.

    Observations and actions are those of :class:`spikectl.wrappers.SB3CompatibleEnv`;
    rewards float32 [num_envs]; ``infos[i]`` holds ``action_mask``, ``context_index``,
    ``illegal_action``, ``TimeLimit.truncated`` and, unless the environment was reset at
    this step, ``spikes`` and ``target_spiked``. With the same seed it equals SB3's
    ``DummyVecEnv`` of ``sb3_compatible`` environments step by step (tested).

    Attributes (``get_attr`` / ``set_attr``) are those of the batched environment, shared
    by all its environments; the only per-environment method is ``action_masks``.
    """

    def __init__(
        self,
        env: NeuronControlVectorEnv | gym.vector.VectorEnv,
        *,
        flatten: bool = True,
        illegal_action: str = "do_nothing",
    ) -> None:
        vector_env = env.unwrapped
        if not isinstance(vector_env, NeuronControlVectorEnv):
            raise TypeError(
                "sb3_vec_env wraps a spikectl NeuronControlVectorEnv (or gymnasium.make_vec of "
                f"a spikectl id), got {type(vector_env).__name__}"
            )
        if isinstance(vector_env, FlatNeuronControlVectorEnv):
            raise TypeError(
                "sb3_vec_env takes the batched paper environment (gymnasium.make_vec of a "
                "paper id such as spikectl/NeuronControl-v0); the flat ids are already flat"
            )
        check_illegal_action(illegal_action)
        self.vector_env = vector_env
        self.illegal_action = illegal_action
        self.observation_codec = observation_for(vector_env, flatten)
        k = vector_env.n_observed
        super().__init__(vector_env.num_envs, self.observation_codec.space, spaces.Discrete(k + 1))
        self._masks = np.zeros((self.num_envs, k + 1), dtype=bool)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray | dict[str, np.ndarray]:
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        observation, infos = self.vector_env.reset(seed=seeds, options=self._reset_options_now())
        self._masks[:] = infos["action_mask"]
        self.reset_infos = [self._reset_info(infos, i) for i in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return self.observation_codec(observation)

    def _reset_options_now(self) -> dict[str, Any] | None:
        """SB3's per-environment options as the batched environment's one dict."""
        if not any(self._options):
            return None
        if any(set(options) != {"context"} for options in self._options):
            raise ValueError(
                "set_options: the only reset option is 'context', given for every "
                f"environment or none; got {self._options}"
            )
        return {"context": [options["context"] for options in self._options]}

    @staticmethod
    def _reset_info(infos: dict[str, np.ndarray], i: int) -> dict[str, Any]:
        return {"action_mask": infos["action_mask"][i], "context_index": infos["context_index"][i]}

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(): call step(actions)")
        actions, self._actions = self._actions, None
        n_actions = self.action_space.n
        rule = f"integers in 0..{n_actions - 1} (0 does nothing)"
        if actions.shape != (self.num_envs,) or actions.dtype.kind not in "iu":
            raise ValueError(bad_shape_message(actions, self.num_envs, rule))
        if actions.min() < 0 or actions.max() >= n_actions:
            raise ValueError(bad_actions_message(
                actions, (actions < 0) | (actions >= n_actions), "are out of range",
                f"actions must be {rule}",
            ))  # fmt: skip
        actions, illegal = legal_or_nothing(actions, self._masks, self.illegal_action)
        env_actions = to_env_action(actions)
        observation, rewards, terminated, truncated, infos = self.vector_env.step(env_actions)
        dones = terminated | truncated
        step_infos = [
            {
                "action_mask": infos["action_mask"][i],
                "context_index": infos["context_index"][i],
                "spikes": infos["spikes"][i],
                "target_spiked": bool(infos["target_spiked"][i]),
                "illegal_action": bool(illegal[i]),
                "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
            }
            for i in range(self.num_envs)
        ]
        observation = self.observation_codec(observation)
        self._masks[:] = infos["action_mask"]
        if dones.any():
            for i in np.flatnonzero(dones):
                step_infos[i]["terminal_observation"] = _row(observation, i)
            reset_observation, reset_infos = self.vector_env.reset(options={"reset_mask": dones})
            observation = self.observation_codec(reset_observation)
            self._masks[:] = reset_infos["action_mask"]
            for i in np.flatnonzero(dones):
                self.reset_infos[i] = self._reset_info(reset_infos, i)
        return observation, rewards.astype(np.float32), dones, step_infos

    def action_masks(self) -> np.ndarray:
        """Legal actions of every environment now: bool [num_envs, k + 1]."""
        return self._masks.copy()

    def _action_mask_of(self, i: int) -> np.ndarray:
        return self._masks[i].copy()

    def close(self) -> None:
        self.vector_env.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        indices = list(self._get_indices(indices))
        if attr_name == "action_masks":
            return [functools.partial(self._action_mask_of, i) for i in indices]
        value = getattr(self.vector_env, attr_name)
        return [value for _ in indices]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        if sorted(self._get_indices(indices)) != list(range(self.num_envs)):
            raise ValueError(
                f"set_attr({attr_name!r}): the environments are one batch and share their "
                "attributes; set it for all of them (indices=None)"
            )
        setattr(self.vector_env, attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        if method_name != "action_masks":
            raise AttributeError(
                f"the environments are stepped as one batch and have no per-environment "
                f"method {method_name!r}; call it on .vector_env (only 'action_masks' is "
                "per environment)"
            )
        methods: list[Callable[..., Any]] = self.get_attr(method_name, indices)
        return [method(*method_args, **method_kwargs) for method in methods]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.render_mode != "rgb_array":
            warnings.warn(
                f"the render mode is {self.render_mode!r}; images need render_mode='rgb_array'",
                stacklevel=2,
            )
            return [None] * self.num_envs
        return list(self.vector_env.render())


def _row(observation: np.ndarray | dict[str, np.ndarray], i: int) -> Any:
    if isinstance(observation, dict):
        return {key: value[i].copy() for key, value in observation.items()}
    return observation[i].copy()
