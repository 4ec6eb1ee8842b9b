"""The pieces every Q-learner of the loop shares (the double-Q learner's, the guided
learner's and PQN's): epsilon-greedy collection on the online network, the online and
target networks (``spikectl.training.agent_network`` builds the agent's) and the
auxiliary next-voltage head, the learning-rate setter a CUDA graph can read, one gradient
step, the metrics row of running loss sums, and the sampled episodes as the networks'
sequence input with the losses every Q-learner computes alike (the TD regression and the
auxiliary next-voltage loss). The double-Q maths itself is in ``learners/dqn.py``.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from spikectl.agents import make_voltage_predictor
from spikectl.agents.features import normalised_voltage
from spikectl.agents.greedy import GreedyController
from spikectl.envs.env_support import random_legal_actions
from spikectl.seeds import AUX_HEAD_STREAM, torch_seed
from spikectl.training.agent_network import build_network
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.replay import EpisodeBatchArrays


class EpsilonGreedyPolicy(GreedyController):
    """Acts with the online network's step forward, carrying one hidden state per episode.

    With probability epsilon (per step and episode) a random legal action replaces the
    greedy one: uniform over the legal actions (``explore_do_nothing=None``, the paper),
    or "do nothing" with probability ``explore_do_nothing`` and otherwise a uniform legal
    stimulation. A new instance starts every batch of episodes.
    """

    def __init__(
        self,
        network: torch.nn.Module,
        epsilon: float,
        rng: np.random.Generator,
        device: str,
        explore_do_nothing: float | None = None,
    ) -> None:
        super().__init__(network, device)
        self.epsilon, self.rng, self.explore_do_nothing = epsilon, rng, explore_do_nothing

    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        greedy = super().__call__(observations, action_mask)  # [S]
        if self.epsilon <= 0:
            return greedy
        return explore(greedy, action_mask, self.epsilon, self.rng, self.explore_do_nothing)


def explore(
    greedy: np.ndarray,
    action_mask: np.ndarray,
    epsilon: float,
    rng: np.random.Generator,
    explore_do_nothing: float | None,
) -> np.ndarray:
    """Epsilon-greedy: greedy actions [S] with each replaced, with probability epsilon, by
    a random legal one (the draws every policy of a run makes, in this order)."""
    exploring = rng.random(greedy.shape[0]) < epsilon  # [S]
    if explore_do_nothing is None:
        random_actions = random_legal_actions(action_mask, rng)
    else:
        # A random stimulation, replaced by do nothing with probability explore_do_nothing.
        stimulations = action_mask.copy()
        stimulations[:, 0] = False
        random_actions = random_legal_actions(stimulations, rng)
        nothing = rng.random(greedy.shape[0]) < explore_do_nothing
        random_actions[nothing] = -1
    return np.where(exploring, random_actions, greedy)


def build_networks(config) -> tuple[torch.nn.Module, torch.nn.Module]:
    """Online and target networks of an Experiment (:func:`build_network` and a copy)."""
    online = build_network(config)
    target = copy.deepcopy(online)
    target.requires_grad_(False)
    return online, target


def build_predictor(config, online: torch.nn.Module) -> torch.nn.Module | None:
    """The auxiliary next-voltage head when ``aux_voltage_weight > 0``, seeded from
    ``config.train.seed`` on a stream of its own (the Q-network's initialisation is unchanged)."""
    if config.learner.aux_voltage_weight <= 0:
        return None
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(torch_seed(config.train.seed, AUX_HEAD_STREAM))
        predictor = make_voltage_predictor(online)
    return predictor.to(config.train.device)


def set_learning_rate(optimizer: torch.optim.Optimizer, learning_rate: float) -> None:
    """Set every parameter group's learning rate, in place where it is a device tensor
    that a CUDA graph reads (``spikectl.training.cuda_graphs``). The schedule is a pure
    function of the episode count, so a resumed run needs no scheduler state."""
    for group in optimizer.param_groups:
        if isinstance(group["lr"], torch.Tensor):
            group["lr"].fill_(learning_rate)
        else:
            group["lr"] = learning_rate


class QLearner:
    """What every Q-learner of the loop does alike, given ``settings`` (a
    :class:`~spikectl.training.learners.q_settings.QSettings`), ``total_episodes``,
    ``network``, ``rng``, ``device``, ``predictor`` and running loss sums: collect
    epsilon-greedily on the online network, drawing from the run's generator, and report
    the metrics row (``updates``, ``epsilon`` and the mean losses since the last row)."""

    settings: Any
    total_episodes: int
    network: torch.nn.Module
    predictor: torch.nn.Module | None
    rng: np.random.Generator
    device: str
    updates: int
    loss_sum: float
    aux_loss_sum: float
    loss_count: int

    def epsilon(self, episode: int) -> float:
        return self.settings.epsilon(episode, self.total_episodes)

    def collection_policy(self, episode: int) -> EpsilonGreedyPolicy:
        return EpsilonGreedyPolicy(
            self.network, self.epsilon(episode), self.rng, self.device,
            self.settings.explore_do_nothing,
        )  # fmt: skip

    def row_metrics(self, episode: int) -> dict[str, float]:
        """The means since the last row (NaN without updates); the sums start again."""
        n = self.loss_count
        row = {
            "updates": self.updates,
            "epsilon": self.epsilon(episode),
            "loss": self.loss_sum / n if n else math.nan,
            "aux_loss": self.aux_loss_sum / n if n and self.predictor is not None else math.nan,
        }
        self.loss_sum, self.aux_loss_sum, self.loss_count = 0.0, 0.0, 0
        return row

    def progress(self, episode: int) -> dict[str, str]:
        return {"eps": f"{self.epsilon(episode):.2f}"}


def gradient_step(learner: Any, loss: torch.Tensor) -> None:
    """One Adam step on ``loss`` over ``learner.trained`` (clipped to the settings'
    ``max_grad_norm`` when it is > 0), counted in ``learner.updates``; a NaN or infinite
    loss stops the run first (:class:`LossDiverged`)."""
    if not torch.isfinite(loss):
        raise LossDiverged(loss.item(), learner.updates + 1)
    learner.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if learner.settings.max_grad_norm > 0:
        torch.nn.utils.clip_grad_norm_(learner.trained, learner.settings.max_grad_norm)
    learner.optimizer.step()
    learner.updates += 1
    learner.loss_count += 1


def sequence_observations(batch: EpisodeBatchArrays, device: str) -> dict[str, torch.Tensor]:
    """Stored episodes → the networks' sequence input, observations 0..N (N + 1 steps)."""
    size, length = batch.actions.shape
    voltage = torch.as_tensor(batch.voltage, device=device)  # [B, N+1, n]
    actions = torch.as_tensor(batch.actions, device=device)  # [B, N]
    no_action = torch.full((size, 1), -1, dtype=torch.long, device=device)
    observations = {
        "voltage": voltage,
        "last_action": torch.cat([no_action, actions], dim=1),  # [B, N+1]
        "step": torch.arange(length + 1, device=device).expand(size, -1),  # [B, N+1]
        "target": torch.as_tensor(batch.targets, device=device)[:, None].expand(-1, length + 1),
        "pattern": torch.as_tensor(batch.patterns, device=device, dtype=torch.float32)[
            :, None
        ].expand(-1, length + 1, -1),  # [B, N+1, N]
    }
    if batch.latency_steps > 0:
        # Observation t carries the actions chosen at t - L .. t - 1 (-1 before the start).
        latency = batch.latency_steps
        before = torch.full((size, latency), -1, dtype=torch.long, device=device)
        padded = torch.cat([before, actions], dim=1)  # [B, L + N]
        observations["actions_in_flight"] = padded.unfold(1, latency, 1)  # [B, N+1, L]
    return observations


def batch_tensors(batch: EpisodeBatchArrays, device: str) -> dict[str, torch.Tensor]:
    """Sampled episodes as the tensors the losses read (``obs_seq`` is a nested dict)."""
    return {
        "obs_seq": sequence_observations(batch, device),
        "actions": torch.as_tensor(batch.actions, device=device),  # [B, N]
        "rewards": torch.as_tensor(batch.rewards, device=device),  # [B, N]
        "legal": torch.as_tensor(batch.action_masks, device=device)[:, None],  # [B, 1, n+1]
    }


def online_forward(
    online, obs_seq: dict[str, torch.Tensor], with_features: bool
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The sequence forward from a zero state: Q-values [B, N + 1, n + 1] and, when
    ``with_features`` (an auxiliary head reads them), the encoder's features
    [B, N + 1, (n,) D] (else None)."""
    if not with_features:
        q_values, _ = online(obs_seq)  # [B, N+1, n+1]
        return q_values, None
    features, _ = online.encode(obs_seq)  # [B, N+1, (n,) D]
    return online.q_values(features, obs_seq), features  # [B, N+1, n+1]


def td_regression_loss(q_taken: torch.Tensor, td_target: torch.Tensor, loss: str) -> torch.Tensor:
    """Mean over batch and steps of (q_taken - td_target)^2 (``"mse"``) or its Huber
    form with delta 1 (``"huber"``)."""
    if loss == "huber":
        return F.smooth_l1_loss(q_taken, td_target)
    return F.mse_loss(q_taken, td_target)


def next_voltage_loss(
    online, predictor, features: torch.Tensor, obs_seq: dict[str, torch.Tensor],
    actions: torch.Tensor,
) -> torch.Tensor:  # fmt: skip
    """The auxiliary loss: MSE of the predictor's every-neuron next normalised voltage,
    read from the features at t [B, N + 1, (n,) D] and the action at t [B, N]."""
    next_voltage = normalised_voltage(
        obs_seq["voltage"][:, 1:], online.v_rest_mV, online.v_threshold_mV
    )  # [B, N, n]
    predicted = predictor(features[:, :-1], actions)  # [B, N, n]
    return F.mse_loss(predicted, next_voltage)
