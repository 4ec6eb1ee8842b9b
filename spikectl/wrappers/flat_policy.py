"""A policy trained on a flat id, played as a controller: how a generic RL agent (CleanRL,
Stable-Baselines3, TorchRL, skrl, ...) is scored on the benchmark suite.

A network trained on ``spikectl/NeuronControlFlat-v0`` reads the flat observation
(:class:`~spikectl.wrappers.conventions.FlatObservation`) and writes zero-based actions;
the suite, ``spikectl.envs.rollout.evaluate_policy`` and the real-time rig play
controllers, which read the paper's observation and write its actions
(:mod:`spikectl.envs.controller`). :class:`FlatPolicyController` is the translation,
the same one the flat environments apply, so a policy acts on the suite's networks
exactly as it acted on the flat id::

    controller = FlatPolicyController.for_env(greedy_actions, gym.make(FLAT_ENV_ID))
    result = suite.score("paper", "test", lambda seed: controller)

``policy(observations, action_mask) -> actions`` takes float32 [S, D] flat observations
and the int8 [S, k + 1] action masks of S environments and returns S zero-based
actions; ``reset`` (optional) is called when every environment starts a new episode,
for a policy with memory (an LSTM's state) to clear it. An illegal action (the target
neuron) does nothing, as on the flat ids by default.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from spikectl.wrappers.conventions import (
    MASK_DTYPE,
    FlatObservation,
    legal_or_nothing,
    observation_for,
    to_env_action,
)
from spikectl.wrappers.flat_env import FlatEnv

FlatPolicy = Callable[[np.ndarray, np.ndarray], Any]
"""(observations float32 [S, D], action_mask int8 [S, k + 1]) -> zero-based actions [S]."""


class FlatPolicyError(ValueError):
    """A flat policy returned something no flat environment accepts: the wrong number of
    actions, non-integers, or actions outside 0..k (the message names which)."""


class FlatPolicyController:
    """A policy of the flat conventions as a batched controller (see the module docstring).

    ``observation`` is the :class:`FlatObservation` of the environment the policy was
    trained on (:meth:`for_env` builds it from that environment), so the observations
    are scaled and laid out as in training.
    """

    def __init__(
        self,
        policy: FlatPolicy,
        observation: FlatObservation,
        reset: Callable[[], None] | None = None,
    ) -> None:
        if not callable(policy):
            raise TypeError(f"policy must be callable, got {type(policy).__name__}")
        if not observation.flatten:
            raise ValueError("FlatPolicyController reads flat observations (flatten=True)")
        self.policy = policy
        self.observation = observation
        self._reset = reset

    @classmethod
    def for_env(
        cls, policy: FlatPolicy, env: Any, reset: Callable[[], None] | None = None
    ) -> FlatPolicyController:
        """The controller of ``policy`` as trained on ``env`` (a spikectl environment or
        ``gymnasium.make`` / ``make_vec`` of a spikectl id, flat or not)."""
        base = env.unwrapped
        if isinstance(base, FlatEnv):  # a flat id's single env holds the paper env
            base = base.env.unwrapped
        return cls(policy, observation_for(base, flatten=True), reset)

    def reset(self) -> None:
        if self._reset is not None:
            self._reset()

    def act_batch(
        self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]
    ) -> np.ndarray:
        flat = np.asarray(self.observation(dict(observations)), dtype=np.float32)  # [S, D]
        mask = np.asarray(infos["action_mask"]).astype(MASK_DTYPE)  # [S, k + 1]
        actions = self._checked(self.policy(flat, mask), len(flat), mask.shape[1])
        actions, _ = legal_or_nothing(actions, mask, "do_nothing")
        return to_env_action(actions)

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        batch = {key: np.asarray(value)[None] for key, value in observation.items()}
        return int(self.act_batch(batch, {"action_mask": np.asarray(info["action_mask"])[None]})[0])

    @staticmethod
    def _checked(actions: Any, count: int, width: int) -> np.ndarray:
        if hasattr(actions, "detach"):  # a torch tensor
            actions = actions.detach().cpu().numpy()
        actions = np.asarray(actions).reshape(-1)
        if actions.shape != (count,):
            raise FlatPolicyError(
                f"the flat policy returned {actions.size} actions for {count} observations"
            )
        if not np.issubdtype(actions.dtype, np.integer):
            raise FlatPolicyError(f"the flat policy returned {actions.dtype} actions, not integers")
        if actions.min() < 0 or actions.max() >= width:
            raise FlatPolicyError(
                f"the flat policy returned actions outside 0..{width - 1} "
                f"(min {actions.min()}, max {actions.max()})"
            )
        return actions.astype(np.int64)


__all__ = ["FlatPolicy", "FlatPolicyController", "FlatPolicyError"]
