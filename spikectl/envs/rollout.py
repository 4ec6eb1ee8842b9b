"""Run controllers on every context of a set at once, through the vector environment.

What plays is a controller (:mod:`spikectl.envs.controller`: ``reset()`` and
``act_batch(observations, infos)``; one without a batched form plays a copy per
sub-environment), or a bare *policy* function ``policy(observations, action_mask) ->
actions`` on batches ([num_envs, ...] arrays in, int [num_envs] out), as the learners'
exploration policies are. A controller gets the observations as the environment gives
them; a bare policy, like the episodes' stored ``voltage``, reads them as a
potential-reading agent does (under spikes-only sensing, each spike as a potential at
threshold: :func:`~spikectl.envs.sensing.with_sensed_potentials`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.controller import Controller, batched
from spikectl.envs.sensing import VOLTAGE_KEY, with_sensed_potentials
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions

Policy = Callable[[dict[str, np.ndarray], np.ndarray], np.ndarray]
"""A bare batched policy: (observations, action_mask [S, n + 1]) -> int64 [S]."""


@dataclass(frozen=True)
class EpisodeBatch:
    """One episode in each sub-environment of a vector environment."""

    voltage: np.ndarray
    """[S, N + 1, n] float32 observed potentials before each step and after the last
    (under spikes-only sensing the spikes as potentials: V_th where a neuron spiked at
    the step just simulated, V_r elsewhere)."""
    actions: np.ndarray
    """[S, N] int64 actions taken."""
    rewards: np.ndarray
    """[S, N] float64 rewards."""
    spikes: np.ndarray
    """[S, N, n] bool spikes of every neuron."""
    action_mask: np.ndarray
    """[S, n + 1] bool legal actions (constant within an episode)."""
    context_index: np.ndarray
    """[S] index of each episode's context in the environment's set."""

    @property
    def returns(self) -> np.ndarray:
        """[S] undiscounted return per episode."""
        return self.rewards.sum(axis=1)


def _batch_actor(policy: Controller | Policy) -> Callable[[dict, dict, dict], np.ndarray]:
    """(observations, what an agent reads of them, infos) -> actions of a controller
    (reset here; it gets the observations) or a bare policy (it gets what an agent reads)."""
    if isinstance(policy, Controller):
        controller = batched(policy)
        controller.reset()
        return lambda observations, read, infos: controller.act_batch(observations, infos)
    if not callable(policy):
        raise TypeError(
            f"{type(policy).__name__} is neither a controller (reset() and act(observation, "
            "info)) nor a policy function (observations, action_mask) -> actions"
        )
    return lambda observations, read, infos: policy(read, infos["action_mask"].astype(bool))


def run_episodes(
    env: NeuronControlVectorEnv,
    context_indices: np.ndarray | list[int],
    policy: Controller | Policy,
) -> EpisodeBatch:
    """One episode of ``policy`` (a controller, or a bare policy function) in each
    sub-environment, on the given contexts of its set.

    ``context_indices`` has one index per sub-environment (``env.num_envs`` of them).
    A controller is reset before the first step.
    """
    act = _batch_actor(policy)
    # With hidden neurons (an extension) only the k observable ones are seen.
    size, length, n = env.num_envs, env.episode_length, env.n_observed
    observations, infos = env.reset(options={"context": [int(i) for i in context_indices]})
    voltage = np.zeros((size, length + 1, n), dtype=np.float32)
    actions = np.zeros((size, length), dtype=np.int64)
    rewards = np.zeros((size, length))
    spikes = np.zeros((size, length, n), dtype=bool)
    action_mask = infos["action_mask"].astype(bool)  # int8 in the infos
    rest, threshold = env.params.v_rest_mV, env.params.v_threshold_mV
    read = with_sensed_potentials(observations, rest, threshold)
    voltage[:, 0] = read[VOLTAGE_KEY]
    for t in range(length):
        actions[:, t] = act(observations, read, infos)
        observations, rewards[:, t], _, _, infos = env.step(actions[:, t])
        read = with_sensed_potentials(observations, rest, threshold)
        voltage[:, t + 1] = read[VOLTAGE_KEY]
        spikes[:, t] = infos["spikes"]
    return EpisodeBatch(
        voltage=voltage,
        actions=actions,
        rewards=rewards,
        spikes=spikes,
        action_mask=action_mask,
        context_index=np.asarray(context_indices, dtype=np.int64),
    )


def evaluate_policy(
    contexts: ContextSet,
    policy: Controller | Policy,
    *,
    extensions: Extensions | None = None,
    seed: int | None = None,
) -> EpisodeBatch:
    """One episode of ``policy`` (a controller or a bare policy function) on every
    context of a set, all in one batch, under the set's own neuron parameters (with the
    environment-level ``extensions``, whose draws start from ``seed``)."""
    env = NeuronControlVectorEnv(num_envs=len(contexts), contexts=contexts, extensions=extensions)
    if seed is not None:
        env.reset(seed=seed)
    episodes = run_episodes(env, np.arange(len(contexts)), policy)
    env.close()
    return episodes
