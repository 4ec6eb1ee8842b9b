"""Recurrent double Q-learning over whole episodes (docs/training.md, paper Appendix D):
the first learner of the training loop, readable top to bottom.

Each round the loop collects ``num_envs`` episodes with :meth:`DQNLearner.collection_policy`
(epsilon-greedy on the online network's step forward); the learner stores them in its
episodic buffer (:meth:`DQNLearner.observe`), then makes ``updates_per_round`` gradient
updates, each on ``batch_size`` whole episodes sampled uniformly
(:meth:`DQNLearner.update`): the double-Q TD loss over ``n_step`` observed rewards (1 in
the paper; :func:`losses_on_tensors`), with ``aux_voltage_weight > 0`` plus an auxiliary
next-voltage loss, Adam with an optional gradient-norm clip and a linearly decaying
learning rate, then a soft update of the target network. Exploration and replay sampling
draw from the run's generator. Its settings are ``dqn_config.DQNConfig``; its stacked
form (K seeds in one computation) is ``dqn_stacked``; the pieces it shares with the
other Q-learners are ``q_learning``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from spikectl.agents import masked_q
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import EpisodeBatch
from spikectl.training.learners.dqn_config import DQNConfig
from spikectl.training.learners.q_learning import (
    QLearner,
    batch_tensors,
    build_networks,
    build_predictor,
    gradient_step,
    next_voltage_loss,
    online_forward,
    set_learning_rate,
    td_regression_loss,
)
from spikectl.training.replay import EpisodeBatchArrays, EpisodeReplay


class DQNLearner(QLearner):
    """One seed's recurrent double-Q learner (``Experiment.learner`` a DQNConfig)."""

    metric_fields = ("epsilon", "aux_loss")
    counter_and_replay_keys = ("replay", "updates", "loss_sum", "aux_loss_sum", "loss_count")
    """The entries of :meth:`state_dict` that are not networks or the optimiser (a stacked
    group keeps those stacked, ``dqn_stacked``)."""

    def __init__(self, config, train_set: ContextSet, rng: np.random.Generator) -> None:
        self.settings = config.learner
        self.total_episodes = config.total_episodes
        self.device = config.train.device
        self.rng = rng
        self.network, self.target = build_networks(config)
        self.predictor = build_predictor(config, self.network)
        self.trained = [
            parameter
            for module in (self.network, self.predictor)
            if module is not None
            for parameter in module.parameters()
        ]
        self.optimizer = torch.optim.Adam(self.trained, lr=self.settings.learning_rate)
        self.replay = EpisodeReplay(
            self.settings.buffer_size, config.env.n_observed, config.env.episode_length,
            latency_steps=config.env.extensions.latency_steps,
        )  # fmt: skip
        self.targets = np.array([c.observed_target for c in train_set], dtype=np.int64)
        self.patterns = np.stack([c.pattern for c in train_set]).astype(np.int8)
        self.updates, self.loss_count = 0, 0
        self.loss_sum, self.aux_loss_sum = 0.0, 0.0

    def observe(self, episodes: EpisodeBatch, contexts: np.ndarray) -> None:
        self.replay.add(
            episodes.voltage, episodes.actions, episodes.rewards, self.targets[contexts],
            self.patterns[contexts], episodes.action_mask,
        )  # fmt: skip

    def update(self, episode: int) -> None:
        settings = self.settings
        if len(self.replay) < max(settings.learning_starts, 1):
            return
        set_learning_rate(self.optimizer, settings.learning_rate_at(episode, self.total_episodes))
        for _ in range(settings.updates_per_round):
            batch = self.replay.sample(settings.batch_size, self.rng)
            gradient_step(self, self.batch_loss(batch, episode))
            soft_update(self.target, self.network, settings.tau)

    def batch_loss(self, batch: EpisodeBatchArrays, episode: int) -> torch.Tensor:
        """The loss of one sampled batch (the TD loss plus the weighted auxiliary loss);
        adds its parts to the running sums the metrics rows report."""
        td, aux = training_losses(
            self.network, self.target, batch, self.settings, self.predictor, self.device
        )
        return self.td_and_aux_loss(td, aux)

    def td_and_aux_loss(self, td: torch.Tensor, aux: torch.Tensor | None) -> torch.Tensor:
        """TD loss plus the weighted auxiliary loss, each added to the running sums."""
        self.loss_sum += td.item()
        self.aux_loss_sum += 0.0 if aux is None else aux.item()
        return td if aux is None else td + self.settings.aux_voltage_weight * aux

    def state_dict(self) -> dict[str, Any]:
        return {
            "network": self.network.state_dict(),
            "target": self.target.state_dict(),
            "predictor": None if self.predictor is None else self.predictor.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "replay": {
                name: torch.from_numpy(np.ascontiguousarray(value))
                if isinstance(value, np.ndarray) else int(value)
                for name, value in self.replay.state_dict().items()
            },
            "updates": int(self.updates),
            "loss_sum": float(self.loss_sum),
            "aux_loss_sum": float(self.aux_loss_sum),
            "loss_count": int(self.loss_count),
        }  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.network.load_state_dict(state["network"])
        self.target.load_state_dict(state["target"])
        if self.predictor is not None:
            self.predictor.load_state_dict(state["predictor"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.load_counters_and_replay(state)

    def load_counters_and_replay(self, state: Mapping[str, Any]) -> None:
        """Restore the buffer and the counters of :meth:`state_dict`."""
        self.replay.load_state_dict(
            {name: value.cpu().numpy() if torch.is_tensor(value) else value
             for name, value in state["replay"].items()}
        )  # fmt: skip
        self.updates, self.loss_count = int(state["updates"]), int(state["loss_count"])
        self.loss_sum, self.aux_loss_sum = float(state["loss_sum"]), float(state["aux_loss_sum"])


# The double-Q maths: the loss of a sampled batch, its n-step target, the target update.


def training_losses(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    settings: DQNConfig,
    predictor: torch.nn.Module | None = None,
    device: str = "cpu",
    return_q_values: bool = False,
    return_features: bool = False,
) -> tuple[torch.Tensor, ...]:
    """The double-Q TD loss over every step of the sampled episodes and, with a
    ``predictor``, the auxiliary next-voltage loss (None without one); with
    ``return_q_values`` also the online Q-values [B, N + 1, n + 1] they were made from,
    with ``return_features`` (last) the encoder's features [B, N + 1, (n,) D]."""
    tensors = batch_tensors(batch, device)
    return losses_on_tensors(
        online, target, tensors, settings, predictor, return_q_values, return_features
    )


def losses_on_tensors(
    online,
    target,
    tensors: dict,
    settings: DQNConfig,
    predictor=None,
    return_q_values: bool = False,
    return_features: bool = False,
) -> tuple[torch.Tensor, ...]:
    """:func:`training_losses` on :func:`batch_tensors`' output; the networks may be
    modules or one seed's view of stacked networks (inside vmap)."""
    obs_seq, actions, rewards, legal = (
        tensors["obs_seq"], tensors["actions"], tensors["rewards"], tensors["legal"]
    )  # fmt: skip
    # One online forward serves the taken-action values, the double-Q argmax and the
    # auxiliary prediction (which reads the encoder's features).
    q_values, features = online_forward(
        online, obs_seq, with_features=predictor is not None or return_features
    )
    q_taken = q_values[:, :-1].gather(2, (actions + 1)[..., None]).squeeze(2)  # [B, N]
    with torch.no_grad():
        # Double Q-learning: the online network picks the action at every observation,
        # the target network evaluates it; illegal actions are masked in the choice.
        best_actions = masked_q(q_values.detach(), legal).argmax(dim=2)  # [B, N+1]
        target_q_values, _ = target(obs_seq)  # [B, N+1, n+1]
        bootstrap = target_q_values.gather(2, best_actions[..., None]).squeeze(2)  # [B, N+1]
        bootstrap[:, -1] = 0.0  # observation N follows the terminal step
        td_target = n_step_targets(rewards, bootstrap, settings.gamma, settings.n_step)  # [B, N]
    td = td_regression_loss(q_taken, td_target, settings.loss)
    aux = None
    if predictor is not None:
        aux = next_voltage_loss(online, predictor, features, obs_seq, actions)
    return (
        (td, aux)
        + ((q_values,) if return_q_values else ())
        + ((features,) if return_features else ())
    )


def n_step_targets(
    rewards: torch.Tensor, bootstrap: torch.Tensor, gamma: float, n_step: int
) -> torch.Tensor:
    """n-step TD targets of every step of whole episodes.

    ``rewards`` [B, N] are r_0 … r_{N-1}; ``bootstrap`` [B, N + 1] is the value of
    observation j (the one before step j), 0 at j = N because the episode terminates
    after step N - 1. For step t:

        td_target_t = Σ_{k<n, t+k<N} γ^k r_{t+k}  +  γ^n · bootstrap[t + n]

    with bootstrap beyond N read as 0. With n = 1 this is r_t + γ · bootstrap[t + 1].
    """
    steps = rewards.shape[1]
    discounts = gamma ** torch.arange(n_step, dtype=rewards.dtype, device=rewards.device)  # [n]
    windows = F.pad(rewards, (0, n_step - 1)).unfold(1, n_step, 1)  # [B, N, n]
    reward_sums = (windows * discounts).sum(dim=2)  # [B, N]
    future = F.pad(bootstrap, (0, n_step - 1))[:, n_step : n_step + steps]  # [B, N]
    return reward_sums + gamma**n_step * future


def td_loss(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    settings: DQNConfig,
) -> torch.Tensor:
    """Double-Q TD loss over every step of the sampled episodes."""
    return training_losses(online, target, batch, settings)[0]


@torch.no_grad()
def soft_update(target: torch.nn.Module, online: torch.nn.Module, tau: float) -> None:
    """target <- tau * online + (1 - tau) * target."""
    for target_param, online_param in zip(target.parameters(), online.parameters(), strict=True):
        target_param.lerp_(online_param, tau)
