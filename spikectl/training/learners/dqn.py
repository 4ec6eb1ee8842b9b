"""Recurrent double Q-learning over whole episodes (docs/training.md, paper Appendix D):
the first learner of the training loop.

Each round the loop collects ``num_envs`` episodes with :meth:`DQNLearner.collection_policy`
(epsilon-greedy on the online network's step forward); the learner stores them in its
episodic buffer (:meth:`DQNLearner.observe`), then makes ``updates_per_round`` gradient
updates, each on ``batch_size`` whole episodes sampled uniformly
(:meth:`DQNLearner.update`): the double-Q TD loss (``dqn_losses``), with
``aux_voltage_weight > 0`` plus an auxiliary next-voltage loss, Adam with an optional
gradient-norm clip and a linearly decaying learning rate, then a soft update of the
target network. Exploration and replay sampling draw from the run's generator.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.agents import make_agent, make_voltage_predictor
from spikectl.agents.greedy import GreedyController
from spikectl.contexts import ContextSet
from spikectl.envs.env_support import random_legal_actions
from spikectl.envs.rollout import EpisodeBatch
from spikectl.training.learners.dqn_losses import soft_update, training_losses
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.replay import EpisodeReplay


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


def build_network(config) -> torch.nn.Module:
    """The online network of an Experiment, initialised from ``config.train.seed``
    without touching Torch's global generator."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.train.seed)
        online = make_agent(
            config.agent.arch, config.env.n_observed, config.env.episode_length,
            config.agent.sizes, params=config.env.params,
        )  # fmt: skip
    return online.to(config.train.device)


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
        torch.manual_seed(np.random.SeedSequence([config.train.seed, 1]).generate_state(1)[0])
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


def epsilon_greedy_collection(learner: Any, episode: int) -> EpsilonGreedyPolicy:
    """A round's collection policy for a learner with an epsilon schedule: epsilon-greedy
    on its online network, drawing from its generator (the double-Q learner's and PQN's)."""
    return EpsilonGreedyPolicy(
        learner.network, learner.epsilon(episode), learner.rng, learner.device,
        learner.settings.explore_do_nothing,
    )  # fmt: skip


def loss_metrics(learner: Any, episode: int) -> dict[str, float]:
    """The metrics row of a learner that keeps running sums of its TD and auxiliary
    losses (``updates``, ``epsilon``, and the means since the last row, NaN without
    updates), then starts the sums again: the double-Q learner's and PQN's."""
    n = learner.loss_count
    row = {
        "updates": learner.updates,
        "epsilon": learner.epsilon(episode),
        "loss": learner.loss_sum / n if n else math.nan,
        "aux_loss": learner.aux_loss_sum / n if n and learner.predictor is not None else math.nan,
    }
    learner.loss_sum, learner.aux_loss_sum, learner.loss_count = 0.0, 0.0, 0
    return row


class DQNLearner:
    """One seed's recurrent double-Q learner (``Experiment.learner`` a DQNConfig)."""

    metric_fields = ("epsilon", "aux_loss")
    labelled_replay = False
    """Whether the buffer keeps a label per step (a learner that imitates sets it)."""
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
        self.connectivity_head = self.build_connectivity_head(config)
        self.trained = [
            parameter
            for module in (self.network, self.predictor, self.connectivity_head)
            if module is not None
            for parameter in module.parameters()
        ]
        self.optimizer = torch.optim.Adam(self.trained, lr=self.settings.learning_rate)
        self.replay = EpisodeReplay(
            self.settings.buffer_size, config.env.n_observed, config.env.episode_length,
            labelled=self.labelled_replay, privileged=self.connectivity_head is not None,
        )  # fmt: skip
        self.targets = np.array([c.observed_target for c in train_set], dtype=np.int64)
        self.patterns = np.stack([c.pattern for c in train_set]).astype(np.int8)
        self.updates, self.loss_count = 0, 0
        self.loss_sum, self.aux_loss_sum = 0.0, 0.0

    def build_connectivity_head(self, config) -> torch.nn.Module | None:
        """A privileged auxiliary head trained beside the network (the guided learner's
        ``connectivity_weight``); None here."""
        return None

    def epsilon(self, episode: int) -> float:
        return self.settings.epsilon(episode, self.total_episodes)

    def collection_policy(self, episode: int) -> EpsilonGreedyPolicy:
        return epsilon_greedy_collection(self, episode)

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
            loss = self.batch_loss(batch, episode)
            if not torch.isfinite(loss):
                raise LossDiverged(loss.item(), self.updates + 1)
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if settings.max_grad_norm > 0:
                torch.nn.utils.clip_grad_norm_(self.trained, settings.max_grad_norm)
            self.optimizer.step()
            soft_update(self.target, self.network, settings.tau)
            self.updates += 1
            self.loss_count += 1

    def batch_loss(self, batch, episode: int) -> torch.Tensor:
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

    def row_metrics(self, episode: int) -> dict[str, float]:
        return loss_metrics(self, episode)

    def progress(self, episode: int) -> dict[str, str]:
        return {"eps": f"{self.epsilon(episode):.2f}"}

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
