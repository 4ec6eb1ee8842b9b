"""Run policies on every context of a set at once, through the vector environment.

A *policy* here is a function ``policy(observations, action_mask) -> actions`` on
batches ([num_envs, ...] arrays in, int [num_envs] out). The reference policies
(do nothing, uniformly random legal actions, replaying the witness) are built by the
``make_*`` functions below; agents plug in the same way.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.env_support import random_legal_actions
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING

Policy = Callable[[dict[str, np.ndarray], np.ndarray], np.ndarray]


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


def do_nothing_policy(observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
    """Never stimulate: scores exactly 0.5 on every context."""
    return np.full(action_mask.shape[0], DO_NOTHING, dtype=np.int64)


def make_random_policy(seed: int) -> Policy:
    """Uniformly random legal actions from a generator seeded with ``seed``."""
    rng = np.random.default_rng(seed)

    def random_policy(observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        return random_legal_actions(action_mask, rng)

    return random_policy


def make_witness_policy(contexts: ContextSet) -> Policy:
    """Replay each context's witness (context i in sub-environment i): return 1.0 where
    the dynamics are deterministic. Actions are in the agent's indexing (observable
    neurons only, when some are hidden)."""
    if any(context.witness is None for context in contexts):
        raise ValueError("some contexts have no witness to replay")
    witnesses = np.stack([context.agent_witness for context in contexts]).astype(np.int64)

    def witness_policy(observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        return witnesses[np.arange(witnesses.shape[0]), observations["step"]]

    return witness_policy


def run_episodes(
    env: NeuronControlVectorEnv, context_indices: np.ndarray | list[int], policy: Policy
) -> EpisodeBatch:
    """One episode of ``policy`` in each sub-environment, on the given contexts of its set.

    ``context_indices`` has one index per sub-environment (``env.num_envs`` of them).
    """
    # With hidden neurons (an extension) only the k observable ones are seen.
    size, length, n = env.num_envs, env.episode_length, env.n_observed
    observations, infos = env.reset(options={"context": [int(i) for i in context_indices]})
    voltage = np.zeros((size, length + 1, n), dtype=np.float32)
    actions = np.zeros((size, length), dtype=np.int64)
    rewards = np.zeros((size, length))
    spikes = np.zeros((size, length, n), dtype=bool)
    action_mask = infos["action_mask"].copy()
    voltage[:, 0] = observations["voltage"]
    for t in range(length):
        actions[:, t] = policy(observations, infos["action_mask"])
        observations, rewards[:, t], _, _, infos = env.step(actions[:, t])
        voltage[:, t + 1] = observations["voltage"]
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
    policy: Policy,
    params: NeuronParams | None = None,
    extensions: Extensions | None = None,
    seed: int | None = None,
) -> EpisodeBatch:
    """One episode of ``policy`` on every context of a set, all in one batch (with the
    environment-level ``extensions``, whose draws start from ``seed``)."""
    env = NeuronControlVectorEnv(
        num_envs=len(contexts), contexts=contexts, params=params, extensions=extensions
    )
    if seed is not None:
        env.reset(seed=seed)
    episodes = run_episodes(env, np.arange(len(contexts)), policy)
    env.close()
    return episodes
