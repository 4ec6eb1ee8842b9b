"""Run controllers on every context of a set at once, through the vector environment.

What plays is a controller (:mod:`spikectl.envs.controller`: ``reset()`` and
``act_batch(observations, infos)``; one without a batched form plays a copy per
sub-environment), or a bare *policy* function ``policy(observations, action_mask) ->
actions`` on batches ([num_envs, ...] arrays in, int [num_envs] out), as the learners'
exploration policies are.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.controller import Controller, batched
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions

Policy = Callable[[dict[str, np.ndarray], np.ndarray], np.ndarray]
"""A bare batched policy: (observations, action_mask [S, n + 1]) -> int64 [S]."""


@dataclass(frozen=True)
class EpisodeBatch:
    """One episode in each sub-environment of a vector environment."""

    voltage: np.ndarray
    """[S, N + 1, n] float32 observed potentials before each step and after the last."""
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


def _batch_actor(policy: Controller | Policy) -> Callable[[dict, dict], np.ndarray]:
    """(observations, infos) -> actions of a controller (reset here) or a bare policy."""
    if isinstance(policy, Controller):
        controller = batched(policy)
        controller.reset()
        return controller.act_batch
    if not callable(policy):
        raise TypeError(
            f"{type(policy).__name__} is neither a controller (reset() and act(observation, "
            "info)) nor a policy function (observations, action_mask) -> actions"
        )
    return lambda observations, infos: policy(observations, infos["action_mask"].astype(bool))


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
    # Spikes-only sensing (an extension) observes no potentials: NaN, not observed.
    voltage[:, 0] = observations.get("voltage", np.nan)
    for t in range(length):
        actions[:, t] = act(observations, infos)
        observations, rewards[:, t], _, _, infos = env.step(actions[:, t])
        voltage[:, t + 1] = observations.get("voltage", np.nan)
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
