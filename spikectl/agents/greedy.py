"""A trained Q-network as a controller: the legal action of highest Q-value.

``GreedyController(network)`` plays any of the four architectures (PyTorch, the
network's ``step`` forward) through the controller interface of
:mod:`spikectl.envs.controller`: ``reset()``, ``act(observation, info)`` on one
environment and ``act_batch(observations, infos)`` on a vector environment's batch. It
is what ``spikectl evaluate``, ``spikectl benchmark``, the real-time rig and the training
loop's greedy evaluations play, and the base of the learners' exploration policies,
which call it as a bare policy function ``policy(observations, action_mask)``.

By default ``act_batch`` runs one batched forward over every sub-environment: fast, and
what metrics.csv's greedy returns were scored with, so ``spikectl evaluate`` repeats them
exactly on the same machine. Its matrix kernels may sum in an order that depends on the
batch size (MKL's sgemm does, on AMD EPYC and on AVX-512 Xeons), so a near-tie between
two Q-values can fall the other way than when the environment is played alone.
``per_environment=True`` runs the network once per sub-environment instead, each as a
batch of one, exactly as ``act`` runs it: the same actions as the real-time rig, in a
batch of any size, on every CPU (docs/realtime.md). For a decision in microseconds,
export the network to a :class:`~spikectl.agents.compiled.CompiledPolicy`.

Under spikes-only sensing the network reads each spike as a potential at threshold
(:func:`~spikectl.envs.sensing.with_sensed_potentials`, at the network's own V_r and
V_th): its normalised potential is the spike, as in the episodes it was trained on.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.agents.heads import greedy_action
from spikectl.agents.observation import observation_batch
from spikectl.envs.controller import check_controller_input
from spikectl.envs.sensing import VOLTAGE_KEY, with_sensed_potentials


class GreedyController:
    """The legal action of highest score under ``network.step`` (scores [S, n + 1]),
    carrying one recurrent state per episode; every episode of a batch starts at step 0
    together, and a step-0 batch starts from the zero state. ``per_environment``: play
    each sub-environment of a batch alone, each from the zero state at its step 0 (see
    the module docstring)."""

    def __init__(
        self,
        network: torch.nn.Module,
        device: str = "cpu",
        per_environment: bool = False,
    ) -> None:
        self.network, self.device, self.state = network, device, None
        self.per_environment = per_environment
        self.row_states: list[Any] = []
        """The recurrent state of each sub-environment, played alone."""

    def reset(self) -> None:
        """Forget the episodes: the next decision starts from the zero state."""
        self.state = None
        self.row_states = []

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        """int64 [S]: the actions of one batched forward over every row."""
        if self.state is not None and not np.any(observations["step"]):
            self.state = None  # a new batch of episodes
        obs = observation_batch(self._read(observations), self.device)
        scores, self.state = self.network.step(obs, self.state)  # [S, n + 1]
        legal = torch.as_tensor(action_mask, device=scores.device)
        return greedy_action(scores, legal).cpu().numpy()  # [S]

    def act_batch(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Any]):
        """int64 [S]: one action per sub-environment."""
        check_controller_input(observations, infos, "GreedyController")
        mask = np.asarray(infos["action_mask"], dtype=bool)  # [S, n + 1]
        if not self.per_environment:
            return self(dict(observations), mask)
        size = mask.shape[0]
        if len(self.row_states) != size:
            self.row_states = [None] * size
        actions = np.empty(size, dtype=np.int64)
        for row in range(size):
            alone = {key: np.array(value[row]) for key, value in observations.items()}
            state = None if alone["step"] == 0 else self.row_states[row]  # as act() does
            actions[row], self.row_states[row] = self._alone(alone, mask[row], state)
        return actions

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The action on one environment's observation (a batch of one)."""
        check_controller_input(observation, info, "GreedyController")
        mask = np.asarray(info["action_mask"], dtype=bool)
        state = None if np.asarray(observation["step"]) == 0 else self.state  # a new episode
        action, self.state = self._alone(observation, mask, state)
        return action

    @torch.no_grad()
    def _alone(self, observation: Mapping[str, Any], mask: np.ndarray, state: Any):
        """(action, new state) of one environment as a batch of one, from fresh copies
        of its arrays: ``act`` and each row of ``act_batch`` run this same computation."""
        observations = {key: np.array(value)[None] for key, value in observation.items()}
        obs = observation_batch(self._read(observations), self.device)
        scores, state = self.network.step(obs, state)  # [1, n + 1]
        legal = torch.as_tensor(mask[None], device=scores.device)
        return int(greedy_action(scores, legal)[0]), state

    def _read(self, observations: Mapping[str, Any]) -> Mapping[str, Any]:
        """What the network reads of the observations: spikes as potentials at its
        threshold under spikes-only sensing, the observations themselves otherwise (a
        network need not carry a voltage range until it plays spikes)."""
        if VOLTAGE_KEY in observations:
            return observations
        network = self.network
        if not hasattr(network, "v_rest_mV") or not hasattr(network, "v_threshold_mV"):
            raise TypeError(
                f"GreedyController: {type(network).__name__} has no v_rest_mV and "
                "v_threshold_mV, which reading spikes as potentials needs"
            )
        return with_sensed_potentials(observations, network.v_rest_mV, network.v_threshold_mV)
