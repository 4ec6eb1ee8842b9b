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
from spikectl.params import NeuronParams
from spikectl.simulator import DO_NOTHING
from spikectl.vector_env import NeuronControlVectorEnv

Policy = Callable[[dict[str, np.ndarray], np.ndarray], np.ndarray]


@dataclass(frozen=True)
class EpisodeBatch:
    """One episode on each context of a set."""

    returns: np.ndarray
    """[S] undiscounted return per context."""
    actions: np.ndarray
    """[S, N] actions taken."""
    spikes: np.ndarray
    """[S, N, n] spikes of every neuron."""


def do_nothing_policy(observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
    """Never stimulate: scores exactly 0.5 on every context."""
    return np.full(action_mask.shape[0], DO_NOTHING, dtype=np.int64)


def make_random_policy(seed: int) -> Policy:
    """Uniformly random legal actions from a generator seeded with ``seed``."""
    rng = np.random.default_rng(seed)

    def random_policy(observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        scores = rng.random(action_mask.shape)  # [S, n + 1]
        scores[~action_mask] = -1.0
        return scores.argmax(axis=1) + DO_NOTHING

    return random_policy


def make_witness_policy(contexts: ContextSet) -> Policy:
    """Replay each context's witness (context i in sub-environment i): return 1.0."""
    if any(context.witness is None for context in contexts):
        raise ValueError("some contexts have no witness to replay")
    witnesses = np.stack([context.witness for context in contexts]).astype(np.int64)  # [S, N]

    def witness_policy(observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        return witnesses[np.arange(witnesses.shape[0]), observations["step"]]

    return witness_policy


def run_episodes(
    contexts: ContextSet, policy: Policy, params: NeuronParams | None = None
) -> EpisodeBatch:
    """One episode of ``policy`` on every context of the set, all in one batch."""
    size, length = len(contexts), contexts.episode_length
    env = NeuronControlVectorEnv(num_envs=size, contexts=contexts, params=params)
    observations, infos = env.reset(options={"context": list(range(size))})
    returns = np.zeros(size)
    actions = np.zeros((size, length), dtype=np.int64)
    spikes = np.zeros((size, length, contexts.n_neurons), dtype=bool)
    for t in range(length):
        actions[:, t] = policy(observations, infos["action_mask"])
        observations, rewards, _, _, infos = env.step(actions[:, t])
        returns += rewards
        spikes[:, t] = infos["spikes"]
    env.close()
    return EpisodeBatch(returns=returns, actions=actions, spikes=spikes)
