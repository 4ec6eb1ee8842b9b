"""The flat batched environment: what ``gymnasium.make_vec`` builds for the flat ids.

:class:`FlatNeuronControlVectorEnv` is the batched paper environment
(:class:`~spikectl.envs.vector_env.NeuronControlVectorEnv`, every network in one call)
that reads its actions and writes its observations in the conventions of
:mod:`spikectl.wrappers.conventions`, so that a generic client gets the batched simulator
from ``gymnasium.make_vec("spikectl/NeuronControlFlat-v0", num_envs)`` as it is. It
subclasses the batched environment rather than wrapping it so that the translation
replaces work (the ``Dict`` observation, the action checks) instead of adding to it.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from spikectl.envs.env_arguments import TARGET_RULE, bad_actions_message, bad_shape_message
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.simulator import DO_NOTHING as PAPER_DO_NOTHING
from spikectl.wrappers.conventions import (
    DO_NOTHING,
    check_illegal_action,
    observation_for,
)


# VectorEnv is named again, after the class it already comes through, for clients that
# recognise a Gymnasium vector env by its direct bases (skrl's wrap_env); the method
# resolution order is the same as with NeuronControlVectorEnv alone.
class FlatNeuronControlVectorEnv(NeuronControlVectorEnv, VectorEnv):
    """``num_envs`` flat environments (:class:`~spikectl.wrappers.flat_env.FlatNeuronControlEnv`)
    stepped as one batch.

    Takes ``num_envs``, ``illegal_action`` (``"do_nothing"`` or ``"raise"``) and the paper
    environment's arguments. Spaces are the flat single ones batched: actions int
    [num_envs] in 0..k (``MultiDiscrete``; any sample is a valid step), observations
    float32 [num_envs, 3k + 3N + 2]. Infos are the batched paper environment's
    (``action_mask`` int8 [num_envs, k + 1], ``context_index``, ``spikes``,
    ``target_spiked``) plus ``illegal_action`` (bool [num_envs]: the action was illegal
    and did nothing) and ``illegal_actions`` (int64 [num_envs], this episode's count),
    each with Gymnasium's ``_key`` mask.

    Autoreset: ``autoreset_mode="NextStep"`` (default: the action sent to an environment
    being reset is ignored) or ``"Disabled"`` (the caller resets ended environments with
    ``reset(options={"reset_mask": ...})``, as TorchRL does; stepping one first raises).
    Seeding (sub-environment i gets ``seed + i``) and reset options (``context``,
    ``reset_mask``) are the batched paper environment's, so with the same seeds it equals
    Gymnasium's sync and async vector environments of the flat id step by step (tested).
    """

    def __init__(
        self,
        num_envs: int = 1,
        illegal_action: str = "do_nothing",
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **kwargs: Any,
    ):
        check_illegal_action(illegal_action)
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.DISABLED):
            raise ValueError(
                f"autoreset_mode must be {AutoresetMode.NEXT_STEP.value!r} or "
                f"{AutoresetMode.DISABLED.value!r}, got {autoreset_mode!r}"
            )
        super().__init__(num_envs, **kwargs)
        self.autoreset_mode = mode
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.illegal_action = illegal_action
        self.observation_codec = observation_for(self, flatten=True)
        self.single_observation_space = self.observation_codec.space
        self.single_action_space = spaces.Discrete(self.n_observed + 1)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._illegal = np.zeros(self.num_envs, dtype=bool)
        self._illegal_actions = np.zeros(self.num_envs, dtype=np.int64)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        observation, infos = super().reset(seed=seed, options=options)
        which = infos["_action_mask"]
        self._illegal_actions[which] = 0
        self._illegal[:] = False
        return observation, self._with_illegal(infos, which)

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        if self._any_needs_reset and self.autoreset_mode is AutoresetMode.DISABLED:
            ended = np.flatnonzero(self._needs_reset).tolist()
            raise ResetNeeded(
                f"sub-environment(s) {ended} ended: with autoreset_mode 'Disabled' reset them "
                "with reset(options={'reset_mask': ...}) before the next step"
            )
        observation, rewards, terminated, truncated, infos = super().step(actions)
        return observation, rewards, terminated, truncated, self._with_illegal(infos, None)

    def _checked_actions(self, actions: Any) -> np.ndarray:
        """Zero-based actions -> the paper's, with the illegal-action rule applied."""
        array = np.asarray(actions)
        if array.shape != (self.num_envs,) or array.dtype.kind not in "iu":
            raise ValueError(bad_shape_message(array, self.num_envs, self._action_rule()))
        # The paper's actions: without hidden neurons or latency the simulator's input itself.
        checked = self._agent_actions if self._indirect else self._actions[:, 0]
        first_illegal = _translate_actions(
            array.astype(np.int64, copy=False), self._legal, self._needs_reset,
            self.illegal_action == "raise", checked, self._illegal, self._illegal_actions,
        )  # fmt: skip
        if first_illegal == _OUT_OF_RANGE:
            raise ValueError(bad_actions_message(
                array, (array < 0) | (array > self.n_observed), "are out of range",
                f"actions must be {self._action_rule()}",
            ))  # fmt: skip
        if first_illegal >= 0:  # nothing was written: every illegal one is still there
            legal = self._legal[self._envs, array]
            raise ValueError(bad_actions_message(
                array, ~legal & ~self._needs_reset, "are illegal", f"{TARGET_RULE} "
                '(see info["action_mask"]; illegal_action="do_nothing" makes it do nothing)',
            ))  # fmt: skip
        return checked

    def _action_rule(self) -> str:
        return f"integers in 0..{self.n_observed} (0 does nothing)"

    def _observation(self, voltage: np.ndarray) -> np.ndarray:
        return self.observation_codec.write(
            voltage, self._observed_targets, self._last_action + 1, self._next_step,
            self._patterns, self._delay.in_flight + 1 if self._delay.steps else None,
            self._spikes if self._spikes_only else None,
            None if self._recording is None else self._recording.mask,
        )  # fmt: skip

    def _with_illegal(
        self, infos: dict[str, np.ndarray], which: np.ndarray | None
    ) -> dict[str, np.ndarray]:
        which = infos["_action_mask"] if which is None else which
        infos["illegal_action"] = self._illegal.copy()
        infos["_illegal_action"] = which.copy()
        infos["illegal_actions"] = self._illegal_actions.copy()
        infos["_illegal_actions"] = which.copy()
        return infos

    def action_masks(self) -> np.ndarray:
        """Legal actions of every environment now: bool [num_envs, k + 1]."""
        return self._legal.copy()


_OUT_OF_RANGE = -2


@numba.njit(cache=True, nogil=True)
def _translate_actions(actions, legal, needs_reset, strict, checked, illegal, counts):
    """The rule of :func:`spikectl.wrappers.conventions.legal_or_nothing` for one batch, in
    one pass (a handful of NumPy calls cost more than the step's simulation at small
    batches): zero-based ``actions`` [B] -> the paper's in ``checked``; an environment
    being autoreset does nothing and restarts its count; an illegal action does nothing,
    is marked in ``illegal`` and counted in ``counts`` (or, ``strict``, is reported).

    Returns -1, the first illegal environment when ``strict`` (nothing written), or
    ``_OUT_OF_RANGE`` for an action outside 0..k.
    """
    width = legal.shape[1]
    for i in range(actions.shape[0]):
        if actions[i] < 0 or actions[i] >= width:
            return _OUT_OF_RANGE
    if strict:
        for i in range(actions.shape[0]):
            if not needs_reset[i] and not legal[i, actions[i]]:
                return i
    for i in range(actions.shape[0]):
        action = actions[i]
        if needs_reset[i]:
            counts[i] = 0
            action = DO_NOTHING
        is_illegal = not legal[i, action]
        illegal[i] = is_illegal
        if is_illegal:
            counts[i] += 1
            action = DO_NOTHING
        checked[i] = action + PAPER_DO_NOTHING
    return -1


__all__ = ["FlatNeuronControlVectorEnv"]
