"""Parallel recurrent Q-learning without replay (PQN; Gallici et al. 2024, "Simplifying
Deep Temporal Difference Learning"): no replay buffer, no target network.

Each round the loop collects ``num_envs`` whole episodes at once with
:meth:`PQNLearner.collection_policy` (epsilon-greedy on the online network, as the DQN
learner collects). :meth:`PQNLearner.update` then makes ``epochs`` passes over exactly
those episodes, each pass in a fresh random order split into minibatches of
``minibatch_size`` whole episodes, and discards them. For a minibatch, one sequence
forward of the online network from the zero state at step 0 gives every step's
Q-values; detached, the same forward gives the bootstrap values, so the targets always
come from the current network (as in the recurrent PQN of purejaxql):

    bootstrap_t = max over legal a of Q(tau_t)[a]   (0 after the terminal step N - 1)
    G_t         = r_t + gamma * ((1 - lambda) * bootstrap_{t+1} + lambda * G_{t+1})
    loss        = mean over minibatch and steps of (Q(tau_t)[a_t] - G_t)^2

with G_t the ``lambda_returns`` (the ``td_target``): Peng's Q(lambda), where lambda = 0
is the one-step target and lambda = 1 the Monte-Carlo return.
What keeps this stable without a target network is LayerNorm in the network's hidden
layers (``AgentSizes.layer_norm``, on in the ``pqn`` preset). The auxiliary next-voltage
loss of the DQN learner may be added (``aux_voltage_weight``). Minibatch orders draw
from the run's generator.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.agents import masked_q
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import EpisodeBatch
from spikectl.training.agent_network import build_network
from spikectl.training.learners import q_learning
from spikectl.training.learners.pqn_config import PQNConfig
from spikectl.training.replay import EpisodeBatchArrays


def q_lambda_returns(
    rewards: torch.Tensor, bootstrap: torch.Tensor, gamma: float, q_lambda: float
) -> torch.Tensor:
    """Peng's Q(lambda) returns of every step of whole episodes.

    ``rewards`` [B, N] are r_0 ... r_{N-1}; ``bootstrap`` [B, N + 1] is the value of
    observation j (the one before step j), 0 at j = N because the episode terminates
    after step N - 1. Backwards from the last step:

        G_t = r_t + gamma * ((1 - lambda) * bootstrap[t + 1] + lambda * G_{t+1}),  G_N = 0

    so G_{N-1} = r_{N-1}; lambda = 0 gives r_t + gamma * bootstrap[t + 1].
    """
    steps = rewards.shape[1]
    lambda_returns = torch.empty_like(rewards)  # [B, N]
    following = bootstrap[:, steps]  # [B]: G_N, the (zero) value after the last step
    for t in reversed(range(steps)):
        following = rewards[:, t] + gamma * (
            (1.0 - q_lambda) * bootstrap[:, t + 1] + q_lambda * following
        )  # [B]
        lambda_returns[:, t] = following
    return lambda_returns


def pqn_losses(
    online: torch.nn.Module,
    tensors: dict,
    settings: PQNConfig,
    predictor: torch.nn.Module | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The Q(lambda) TD loss over every step of a minibatch of whole episodes
    (:func:`~spikectl.training.learners.q_learning.batch_tensors`' output) and, with a
    ``predictor``, the auxiliary next-voltage loss (None without one)."""
    obs_seq, actions, rewards, legal = (
        tensors["obs_seq"], tensors["actions"], tensors["rewards"], tensors["legal"]
    )  # fmt: skip
    q_values, features = q_learning.online_forward(
        online, obs_seq, with_features=predictor is not None
    )
    q_taken = q_values[:, :-1].gather(2, (actions + 1)[..., None]).squeeze(2)  # [B, N]
    with torch.no_grad():
        # No target network: the bootstrap is the current network's own best legal value.
        bootstrap = masked_q(q_values.detach(), legal).max(dim=2).values  # [B, N+1]
        bootstrap[:, -1] = 0.0  # observation N follows the terminal step
        td_target = q_lambda_returns(rewards, bootstrap, settings.gamma, settings.q_lambda)
    td = q_learning.td_regression_loss(q_taken, td_target, settings.loss)  # td_target: [B, N]
    if predictor is None:
        return td, None
    return td, q_learning.next_voltage_loss(online, predictor, features, obs_seq, actions)


def episode_arrays(
    episodes: EpisodeBatch, targets: np.ndarray, patterns: np.ndarray, latency_steps: int = 0
) -> EpisodeBatchArrays:
    """A round's episodes, played with loop latency ``latency_steps``, as the arrays the
    losses read (what the replay buffer would hand out, here kept for one update only)."""
    return EpisodeBatchArrays(
        voltage=episodes.voltage,
        actions=episodes.actions.astype(np.int64),
        rewards=episodes.rewards.astype(np.float32),
        targets=targets,
        patterns=patterns,
        action_masks=episodes.action_mask,
        latency_steps=latency_steps,
    )


def minibatch(arrays: EpisodeBatchArrays, index: np.ndarray) -> EpisodeBatchArrays:
    """Episodes ``index`` of a round."""
    return EpisodeBatchArrays(
        voltage=arrays.voltage[index],
        actions=arrays.actions[index],
        rewards=arrays.rewards[index],
        targets=arrays.targets[index],
        patterns=arrays.patterns[index],
        action_masks=arrays.action_masks[index],
        latency_steps=arrays.latency_steps,
    )


class PQNLearner(q_learning.QLearner):
    """One seed's parallel Q-learner without replay (``Experiment.learner`` a PQNConfig)."""

    metric_fields = ("epsilon", "aux_loss")

    def __init__(self, config, train_set: ContextSet, rng: np.random.Generator) -> None:
        self.settings: PQNConfig = config.learner
        self.total_episodes = config.total_episodes
        self.device = config.train.device
        self.rng = rng
        self.network = build_network(config)
        self.predictor = q_learning.build_predictor(config, self.network)
        self.trained = list(self.network.parameters()) + (
            list(self.predictor.parameters()) if self.predictor is not None else []
        )
        self.optimizer = torch.optim.Adam(self.trained, lr=self.settings.learning_rate)
        self.targets = np.array([c.observed_target for c in train_set], dtype=np.int64)
        self.patterns = np.stack([c.pattern for c in train_set]).astype(np.int8)
        self.latency_steps = config.env.extensions.latency_steps
        self.round: EpisodeBatchArrays | None = None
        """The episodes of the round being learned from (None between rounds: they are
        discarded after the update, so a checkpoint holds none)."""
        self.updates, self.loss_count = 0, 0
        self.loss_sum, self.aux_loss_sum = 0.0, 0.0

    def observe(self, episodes: EpisodeBatch, contexts: np.ndarray) -> None:
        self.round = episode_arrays(
            episodes, self.targets[contexts], self.patterns[contexts], self.latency_steps
        )

    def update(self, episode: int) -> None:
        settings, arrays = self.settings, self.round
        if arrays is None:
            return
        q_learning.set_learning_rate(
            self.optimizer, settings.learning_rate_at(episode, self.total_episodes)
        )
        size = arrays.actions.shape[0]
        for _ in range(settings.epochs):
            order = self.rng.permutation(size)  # [E]: a fresh split into minibatches
            for start in range(0, size, settings.minibatch_size):
                index = order[start : start + settings.minibatch_size]  # [M]
                tensors = q_learning.batch_tensors(minibatch(arrays, index), self.device)
                td, aux = pqn_losses(self.network, tensors, settings, self.predictor)
                loss = td if aux is None else td + settings.aux_voltage_weight * aux
                q_learning.gradient_step(self, loss)
                self.loss_sum += td.item()
                self.aux_loss_sum += 0.0 if aux is None else aux.item()
        self.round = None  # no replay: the episodes are used up

    def state_dict(self) -> dict[str, Any]:
        return {
            "network": self.network.state_dict(),
            "predictor": None if self.predictor is None else self.predictor.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "updates": int(self.updates),
            "loss_sum": float(self.loss_sum),
            "aux_loss_sum": float(self.aux_loss_sum),
            "loss_count": int(self.loss_count),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.network.load_state_dict(state["network"])
        if self.predictor is not None:
            self.predictor.load_state_dict(state["predictor"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.updates, self.loss_count = int(state["updates"]), int(state["loss_count"])
        self.loss_sum, self.aux_loss_sum = float(state["loss_sum"]), float(state["aux_loss_sum"])
        self.round = None


__all__ = ["PQNLearner", "pqn_losses", "q_lambda_returns"]
