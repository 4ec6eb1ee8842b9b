"""The flat environment: one spikectl environment in the ecosystem's conventions.

:class:`FlatEnv` puts any single spikectl environment behind the conventions of
:mod:`spikectl.wrappers.conventions` (zero-based ``Discrete`` actions, a flat float32
``Box`` with finite bounds, int8 masks, illegal actions that do nothing);
:class:`FlatNeuronControlEnv` is the one that ``gymnasium.make`` builds for the flat ids
(``spikectl/NeuronControlFlat-v0`` and the flat twins of the variants). Dynamics,
rewards, seeding and episode ends are the paper environment's, unchanged.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.env_arguments import short_repr
from spikectl.wrappers.conventions import (
    DO_NOTHING,
    check_illegal_action,
    observation_for,
    to_env_action,
)


class FlatEnv(gym.Env):
    """A spikectl environment with zero-based actions, int8 masks and bounded observations.

    ``env`` is a :class:`~spikectl.envs.env.NeuronControlEnv` or ``gymnasium.make`` of a
    paper id. ``flatten``: one float32 vector (default) or the paper's ``Dict`` with a
    clipped voltage and zero-based ``last_action``. ``illegal_action``: ``"do_nothing"``
    (default) or ``"raise"``. ``info`` is the paper environment's plus ``illegal_action``
    (bool: this step's action was illegal and did nothing) and ``illegal_actions`` (int:
    how many this episode); ``action_masks()`` (bool [k + 1]) is the current mask, as
    sb3-contrib's ``MaskablePPO`` reads it.

    It holds the base environment (``self.env``) rather than being a ``gym.Wrapper``:
    Gymnasium's ``check_env`` warns about any wrapper, and this is a new interface to
    the environment, not a layer over the same one. Its ``np_random`` is the base
    environment's, so there is one generator, seeded by ``reset(seed=...)``.
    """

    metadata = NeuronControlEnv.metadata  # render modes, read from the class by gymnasium.make

    def __init__(
        self, env: gym.Env, *, flatten: bool = True, illegal_action: str = "do_nothing"
    ) -> None:
        if not isinstance(env.unwrapped, NeuronControlEnv):
            raise TypeError(
                f"{type(self).__name__} wraps a spikectl NeuronControlEnv (or gymnasium.make of "
                f"a spikectl paper id), got {type(env.unwrapped).__name__}"
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
        self._illegal_actions = 0

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
        self._mask = info["action_mask"].astype(bool)
        self._illegal_actions = 0
        info["illegal_action"] = False
        info["illegal_actions"] = 0
        return self.observation_codec(observation), info

    def step(
        self, action: Any
    ) -> tuple[np.ndarray | dict[str, Any], float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(
                f"action {short_repr(action)} is not in {self.action_space}: 0 does nothing, "
                f"a in 1..{self.action_space.n - 1} stimulates neuron a - 1"
            )
        action = int(action)
        illegal = not self._mask[action]
        if illegal:
            if self.illegal_action == "raise":
                raise ValueError(
                    f"action {action} stimulates the target neuron, which is not a legal action "
                    '(see info["action_mask"]; illegal_action="do_nothing" makes it do nothing)'
                )
            action = DO_NOTHING
            self._illegal_actions += 1
        observation, reward, terminated, truncated, info = self.env.step(to_env_action(action))
        self._mask = info["action_mask"].astype(bool)
        info["illegal_action"] = illegal
        info["illegal_actions"] = self._illegal_actions
        return self.observation_codec(observation), reward, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """Legal actions now: bool [k + 1], entry a for zero-based action a."""
        return self._mask.copy()

    def render(self) -> str | np.ndarray | None:
        return self.env.render()

    def close(self) -> None:
        self.env.close()


class FlatNeuronControlEnv(FlatEnv):
    """
    ## Description

    The paper's task (:class:`~spikectl.envs.env.NeuronControlEnv`, docs/environment.md)
    in the conventions that generic RL libraries take as they are; registered as
    ``spikectl/NeuronControlFlat-v0`` and the flat twins of the variants
    (``spikectl/NeuronControlNoisyFlat-v0``, ...). Same dynamics, rewards, seeding
    and contexts: action a + 1 here is the paper's action a, step for step.

    ## Action Space

    `Discrete(k + 1)`: 0 does nothing, a in 1..k stimulates (observable) neuron a - 1.
    `info["action_mask"]` (int8 [k + 1], 1 = legal) marks the target neuron illegal. An
    illegal action does nothing and sets `info["illegal_action"]`; `info["illegal_actions"]`
    counts them over the episode. `illegal_action="raise"` raises `ValueError` instead
    (the paper environment's rule).

    ## Observation Space

    `Box(low, high, (3k + 3N + 2,), float32)`, finite bounds; layout and bounds in
    :class:`~spikectl.wrappers.conventions.FlatObservation` and docs/environment.md.
    With the defaults (k = n = 8, N = 60): 206 entries, the voltage block in
    [-35.4, 11] (potentials scaled to 0 at rest, 1 at threshold; measurement noise
    and other extensions are clipped into it), every other entry in [-1, 1].

    ## Rewards, Starting State, Episode End

    As in the paper environment: return in [0, 1], termination after N steps, never
    truncation.

    ## Arguments

    `illegal_action` (`"do_nothing"` or `"raise"`) and every argument of
    `NeuronControlEnv` (`contexts`, `split`, `extensions`, ...).

    ## Version History
    * v0: Initial version: zero-based actions, int8 masks, illegal actions do nothing.
    """

    def __init__(self, illegal_action: str = "do_nothing", **kwargs: Any) -> None:
        super().__init__(NeuronControlEnv(**kwargs), illegal_action=illegal_action)


__all__ = ["FlatEnv", "FlatNeuronControlEnv"]
