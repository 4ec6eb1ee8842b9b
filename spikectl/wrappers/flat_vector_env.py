"""The flat batched environment: what ``gymnasium.make_vec`` builds for the flat ids.

:class:`FlatNeuronControlVectorEnv` steps a
:class:`~spikectl.envs.vector_env.NeuronControlVectorEnv` (every network in one call)
and writes its actions, observations and masks in the conventions of
:mod:`spikectl.wrappers.conventions`, so that a generic client gets the batched simulator
from ``gymnasium.make_vec("spikectl/NeuronControlFlat-v0", num_envs)`` as it is.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers.conventions import (
    DO_NOTHING,
    check_illegal_action,
    legal_or_nothing,
    observation_for,
    to_env_action,
)


class FlatNeuronControlVectorEnv(VectorEnv):
    """``num_envs`` flat environments (:class:`~spikectl.wrappers.flat_env.FlatNeuronControlEnv`)
    stepped as one batch.

    Takes ``num_envs``, ``illegal_action`` (``"do_nothing"`` or ``"raise"``) and the paper
    environment's arguments. Spaces are the flat single ones batched: actions int
    [num_envs] in 0..k (``MultiDiscrete``; any sample is a valid step), observations
    float32 [num_envs, 3k + 3N + 2]. Infos are the batched paper environment's
    (``action_mask`` int8 [num_envs, k + 1], ``context_index``, ``spikes``,
    ``target_spiked``) plus ``illegal_action`` (bool [num_envs]) and ``illegal_actions``
    (int64 [num_envs], this episode's count), each with Gymnasium's ``_key`` mask.

    Autoreset (``NEXT_STEP``), seeding (sub-environment i gets ``seed + i``) and reset
    options (``context``, ``reset_mask``) are the batched paper environment's, so with
    the same seeds it equals Gymnasium's sync and async vector environments of the flat
    id step by step (tested). ``self.vector_env`` is the batched paper environment.
    """

    metadata = {**NeuronControlVectorEnv.metadata, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, illegal_action: str = "do_nothing", **kwargs: Any):
        check_illegal_action(illegal_action)
        self.vector_env = base = NeuronControlVectorEnv(num_envs, **kwargs)
        self.illegal_action = illegal_action
        self.num_envs = base.num_envs
        self.render_mode = base.render_mode
        for name in ("contexts", "params", "extensions", "n_neurons", "n_observed"):
            setattr(self, name, getattr(base, name))
        self.episode_length = base.episode_length
        self.observation_codec = observation_for(base, flatten=True)
        self.single_observation_space = self.observation_codec.space
        self.single_action_space = spaces.Discrete(base.n_observed + 1)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._masks = np.zeros((self.num_envs, base.n_observed + 1), dtype=np.int8)
        self._illegal_actions = np.zeros(self.num_envs, dtype=np.int64)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._all_envs = np.ones(self.num_envs, dtype=bool)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        if isinstance(seed, int):
            super().reset(seed=seed)  # seeds self.np_random, as Gymnasium's vector envs do
        observation, infos = self.vector_env.reset(seed=seed, options=options)
        which = infos["_action_mask"]
        self._masks[which] = infos["action_mask"][which]
        self._illegal_actions[which] = 0
        self._autoreset[which] = False
        return self.observation_codec(observation), self._with_illegal(
            infos, np.zeros(self.num_envs, dtype=bool), which
        )

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        actions = np.asarray(actions)
        n_actions = self.single_action_space.n
        if (
            actions.shape != (self.num_envs,)
            or actions.dtype.kind not in "iu"
            or actions.min() < 0
            or actions.max() >= n_actions
        ):
            raise ValueError(
                f"actions must be integers in 0..{n_actions - 1} of shape ({self.num_envs},), "
                f"got {actions.dtype} {actions.shape}: {actions.tolist()}"
            )
        autoreset = self._autoreset
        if autoreset.any():  # their actions are ignored: they start a new episode
            actions = np.where(autoreset, DO_NOTHING, actions)
            self._illegal_actions[autoreset] = 0
        actions, illegal = legal_or_nothing(actions, self._masks, self.illegal_action)
        self._illegal_actions += illegal
        observation, rewards, terminated, truncated, infos = self.vector_env.step(
            to_env_action(actions)
        )
        self._masks[:] = infos["action_mask"]
        self._autoreset = terminated | truncated
        infos = self._with_illegal(infos, illegal, self._all_envs)
        return self.observation_codec(observation), rewards, terminated, truncated, infos

    def _with_illegal(
        self, infos: dict[str, np.ndarray], illegal: np.ndarray, which: np.ndarray
    ) -> dict[str, np.ndarray]:
        infos["illegal_action"] = illegal
        infos["_illegal_action"] = which.copy()
        infos["illegal_actions"] = self._illegal_actions.copy()
        infos["_illegal_actions"] = which.copy()
        return infos

    def action_masks(self) -> np.ndarray:
        """Legal actions of every environment now: bool [num_envs, k + 1]."""
        return self._masks.astype(bool)

    def render(self) -> tuple[str, ...] | tuple[np.ndarray, ...] | None:
        return self.vector_env.render()

    def close_extras(self, **kwargs: Any) -> None:
        self.vector_env.close()


__all__ = ["FlatNeuronControlVectorEnv"]
