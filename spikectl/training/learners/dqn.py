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

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import EpisodeBatch
from spikectl.training.learners.dqn_losses import soft_update, training_losses
from spikectl.training.learners.q_learning import (
    QLearner,
    build_networks,
    build_predictor,
    gradient_step,
    set_learning_rate,
)
from spikectl.training.replay import EpisodeReplay


class DQNLearner(QLearner):
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
        self.stores_target_inputs = self.connectivity_head is not None
        """Whether each stored episode keeps its network's target inputs (privileged)."""
        self.trained = [
            parameter
            for module in (self.network, self.predictor, self.connectivity_head)
            if module is not None
            for parameter in module.parameters()
        ]
        self.optimizer = torch.optim.Adam(self.trained, lr=self.settings.learning_rate)
        self.replay = EpisodeReplay(
            self.settings.buffer_size, config.env.n_observed, config.env.episode_length,
            labelled=self.labelled_replay, privileged=self.stores_target_inputs,
        )  # fmt: skip
        self.targets = np.array([c.observed_target for c in train_set], dtype=np.int64)
        self.patterns = np.stack([c.pattern for c in train_set]).astype(np.int8)
        self.updates, self.loss_count = 0, 0
        self.loss_sum, self.aux_loss_sum = 0.0, 0.0

    def build_connectivity_head(self, config) -> torch.nn.Module | None:
        """A privileged auxiliary head trained beside the network (the guided learner's
        ``connectivity_weight``); None here."""
        return None

    def observe(self, episodes: EpisodeBatch, contexts: np.ndarray) -> None:
        self.add_to_replay(episodes, contexts)

    def add_to_replay(
        self,
        episodes: EpisodeBatch,
        contexts: np.ndarray,
        labels: np.ndarray | None = None,
        target_inputs: np.ndarray | None = None,
    ) -> None:
        """Store finished episodes (with the teacher's labels and the target's inputs
        where the buffer keeps them)."""
        self.replay.add(
            episodes.voltage, episodes.actions, episodes.rewards, self.targets[contexts],
            self.patterns[contexts], episodes.action_mask, labels, target_inputs,
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
