"""Teacher-guided recurrent double Q-learning: the DQN learner that also imitates a
teacher on the states it visits itself, weaned off so that reward can take it further.

Each round the agent collects its episodes as the DQN learner does (epsilon-greedy on
its own network: the states are the student's, as in DAgger). While the imitation
weight is above zero, a teacher (``learners.teachers``) is played beside every finished
episode and labels each step with the action it would have taken; the labels are
stored with the episode. Every update adds to the TD loss (and the auxiliary loss) the
large-margin imitation loss of DQfD (Hester et al. 2018) on the labelled steps,

    imitation_loss = mean over labelled steps of  max_a [Q(h, a) + margin·(a ≠ a_E)] − Q(h, a_E)

which is zero once the teacher's action a_E leads every other by the margin, so it
shapes the ranking of the actions and leaves the values to the TD loss. Its weight
decays linearly to ``imitation_weight_end`` (0: pure Q-learning from then on, and no
more labels). The teacher runs in the training process: its CPU time is part of the
run's, and metrics.csv reports it (``teacher_seconds``).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from spikectl.agents import make_connectivity_predictor, masked_q
from spikectl.config_errors import ConfigError
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import EpisodeBatch
from spikectl.planning import Composition, IdentifyAndPlan, named_composition
from spikectl.seeds import CONNECTIVITY_HEAD_STREAM, torch_seed
from spikectl.training.learners.dqn import DQNLearner, losses_on_tensors
from spikectl.training.learners.q_learning import batch_tensors
from spikectl.training.learners.teachers import (
    TeacherMixedPolicy,
    make_oracle_teacher,
    oracle_labels,
    teacher_labels,
    teacher_refusal,
)
from spikectl.training.replay import EpisodeReplay


def large_margin_loss(
    q_values: torch.Tensor, labels: torch.Tensor, legal: torch.Tensor, margin: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """DQfD's supervised loss and the student's agreement with the teacher.

    q_values [B, N, n + 1] at the labelled observations, labels [B, N] (the teacher's
    actions, < -1 where unlabelled), legal [B, 1, n + 1]. Returns (the mean loss over
    labelled steps, the fraction of them where the student's greedy action is the
    teacher's); both 0 without labelled steps.
    """
    labelled = labels >= -1  # [B, N]
    index = (labels.clamp(min=-1) + 1)[..., None]  # [B, N, 1]
    margins = torch.full_like(q_values, margin).scatter(2, index, 0.0)  # [B, N, n+1]
    best_with_margin = masked_q(q_values + margins, legal).max(dim=2).values  # [B, N]
    q_teacher = q_values.gather(2, index).squeeze(2)  # [B, N]
    count = labelled.sum()
    if count == 0:
        zero = q_values.new_zeros(())
        return zero, zero
    loss = ((best_with_margin - q_teacher) * labelled).sum() / count
    with torch.no_grad():
        greedy = masked_q(q_values, legal).argmax(dim=2)  # [B, N]
        agreement = ((greedy == index.squeeze(2)) & labelled).sum() / count
    return loss, agreement


def connectivity_loss(
    head: torch.nn.Module, features: torch.Tensor, target_inputs: torch.Tensor
) -> torch.Tensor:
    """The privileged auxiliary loss: cross-entropy of the head's every-step guess of each
    observed neuron's synapse onto the target, from the features [B, N + 1, (n,) D],
    against the training network's signs ``target_inputs`` [B, n] (-1, 0, +1), averaged
    over episodes, steps and neurons."""
    logits = head(features)  # [B, N+1, n, 3]
    classes = (target_inputs.long() + 1)[:, None].expand(-1, logits.shape[1], -1)  # [B, N+1, n]
    return F.cross_entropy(logits.flatten(0, 2), classes.flatten())


def teacher_composition(config) -> Composition:
    """The identify teacher's composition for an Experiment: the named controller's on
    its environment, in the form whose every decision is fast (it labels every step),
    or the paper's (``teacher_settings``)."""
    if config.learner.teacher_settings == "task":
        return named_composition(config.env.extensions, config.env.n_observed, fast=True)
    return Composition()


class GuidedDQNLearner(DQNLearner):
    """One seed's teacher-guided learner (``Experiment.learner`` a GuidedConfig)."""

    metric_fields = DQNLearner.metric_fields + (
        "imitation_weight", "imitation_loss", "teacher_agreement", "teacher_seconds",
        "connectivity_loss",
    )  # fmt: skip

    def __init__(self, config, train_set: ContextSet, rng: np.random.Generator) -> None:
        super().__init__(config, train_set, rng)
        # The privileged connectivity head trains beside the network and the voltage
        # head, in one optimiser: the double-Q learner's, made again with the same
        # settings over its parameters and the head's (it draws nothing, has not stepped).
        self.connectivity_head = self.build_connectivity_head(config)
        if self.connectivity_head is not None:
            self.trained += list(self.connectivity_head.parameters())
            self.optimizer = type(self.optimizer)(self.trained, **self.optimizer.defaults)
        self.stores_target_inputs = self.connectivity_head is not None
        """Whether each stored episode keeps its network's target inputs (privileged)."""
        # The buffer keeps the teacher's label of every step (and the target's inputs).
        self.replay = EpisodeReplay(
            self.settings.buffer_size, config.env.n_observed, config.env.episode_length,
            labelled=True, privileged=self.stores_target_inputs,
            latency_steps=config.env.extensions.latency_steps,
        )  # fmt: skip
        self.contexts = list(train_set)
        self.params = config.env.params
        self.extensions = config.env.extensions
        self.teacher_composition = teacher_composition(config)
        if (
            self.settings.teacher == "told-weights"
            and config.env.n_observed != config.env.n_neurons
        ):
            raise ValueError(
                "learner.teacher 'told-weights' needs every neuron observed; "
                f"{config.env.id} hides some (use teacher 'identify')"
            )
        self.oracle = None
        if self.settings.teacher == "oracle":
            self.oracle = make_oracle_teacher(self.contexts, self.params, self.extensions,
                                              self.settings.teacher_width)  # fmt: skip
        self.teacher_seconds = 0.0
        self.num_envs = config.train.num_envs
        self.mixed_policy: TeacherMixedPolicy | None = None
        """This round's policy when the teacher plays some of its episodes, else None."""
        self.imitation_loss_sum, self.agreement_sum, self.imitation_count = 0.0, 0.0, 0
        self.connectivity_loss_sum, self.connectivity_count = 0.0, 0
        # Each training network's observed neurons' synapses onto its target: [C, n].
        self.target_inputs = np.stack(
            [np.sign(c.weights[c.observable, c.target]) for c in train_set]
        ).astype(np.int8)

    @classmethod
    def check_environment(cls, config) -> None:
        """Refuse a run whose teacher cannot play its environment, in one line, before
        any directory is made (a run that never teaches is not refused)."""
        settings = config.learner
        if not settings.teaches:
            return
        problem = teacher_refusal(config.env, settings.teacher, settings.teacher_width,
                                  teacher_composition(config))  # fmt: skip
        if problem is not None:
            oracle = "" if settings.teacher == "oracle" else "train with --teacher oracle, or "
            raise ConfigError(
                ("learner", "teacher"),
                f"{settings.teacher!r} cannot teach on this environment ({problem}); "
                f"{oracle}train without a teacher (--imitation-weight 0 "
                "--imitation-weight-end 0, or the quick preset)",
            )

    def build_connectivity_head(self, config) -> torch.nn.Module | None:
        """The privileged connectivity head when ``connectivity_weight > 0``, seeded from
        ``config.train.seed`` on a stream of its own (the networks' initialisation and the
        voltage head's are unchanged)."""
        if config.learner.connectivity_weight <= 0:
            return None
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(torch_seed(config.train.seed, CONNECTIVITY_HEAD_STREAM))
            head = make_connectivity_predictor(self.network)
        return head.to(config.train.device)

    def imitation_weight(self, episode: int) -> float:
        return self.settings.imitation_weight_at(episode, self.total_episodes)

    def collection_policy(self, episode: int):
        student = super().collection_policy(episode)
        share = self.settings.teacher_share_at(episode, self.total_episodes)
        self.mixed_policy = None
        if share <= 0:
            return student
        # Drawn only while the teacher plays, so runs without it keep their draws.
        teacher_plays = self.rng.random(self.num_envs) < share  # [S]
        # Only the realisable teacher plays (GuidedConfig refuses the other).
        teacher = functools.partial(
            IdentifyAndPlan, self.params,
            self.teacher_composition.with_width(self.settings.teacher_width),
            extensions=self.extensions,
        )  # fmt: skip
        self.mixed_policy = TeacherMixedPolicy(student, teacher_plays, teacher)
        return self.mixed_policy

    def observe(self, episodes: EpisodeBatch, contexts: np.ndarray) -> None:
        played = None
        if self.mixed_policy is not None:  # the teacher's own episodes count too
            self.teacher_seconds += self.mixed_policy.teacher_seconds
            played, self.mixed_policy = self.mixed_policy.teacher_plays, None
        labels = None
        if self.imitation_weight(self.replay.added) > 0:
            started = time.process_time()
            if self.oracle is not None:  # the training networks' plans, each made once
                labels = oracle_labels(self.oracle, contexts, self.extensions)
            else:
                labels = teacher_labels(
                    episodes, [self.contexts[i] for i in contexts], self.settings.teacher,
                    self.params, self.extensions, self.settings.teacher_width,
                    played=played, composition=self.teacher_composition,
                )  # fmt: skip
            self.teacher_seconds += time.process_time() - started
        told = self.target_inputs[contexts] if self.stores_target_inputs else None
        self.replay.add(
            episodes.voltage, episodes.actions, episodes.rewards, self.targets[contexts],
            self.patterns[contexts], episodes.action_mask, labels, told,
        )  # fmt: skip

    def batch_loss(self, batch, episode: int) -> torch.Tensor:
        weight = self.imitation_weight(episode)
        head = self.connectivity_head is not None
        if weight <= 0 and not head:
            return super().batch_loss(batch, episode)
        tensors = batch_tensors(batch, self.device)
        if self.stores_target_inputs:
            target_inputs = torch.as_tensor(batch.target_inputs, device=self.device)  # [B, n]
        td, aux, q_values, *features = losses_on_tensors(
            self.network, self.target, tensors, self.settings, self.predictor,
            return_q_values=True, return_features=head,
        )  # fmt: skip
        loss = self.td_and_aux_loss(td, aux)
        if head:
            connectivity = connectivity_loss(self.connectivity_head, features[0], target_inputs)
            self.connectivity_loss_sum += connectivity.item()
            self.connectivity_count += 1
            loss = loss + self.settings.connectivity_weight * connectivity
        if weight <= 0:
            return loss
        labels = torch.as_tensor(batch.labels, device=self.device)  # [B, N]
        legal = torch.as_tensor(batch.action_masks, device=self.device)[:, None]  # [B, 1, n+1]
        imitation, agreement = large_margin_loss(
            q_values[:, :-1], labels, legal, self.settings.imitation_margin
        )
        self.imitation_loss_sum += imitation.item()
        self.agreement_sum += agreement.item()
        self.imitation_count += 1
        return loss + weight * imitation

    def row_metrics(self, episode: int) -> dict[str, float]:
        # Means over the updates since the last row that imitated (the row where the
        # weight reaches 0 has updates of both kinds).
        n = self.imitation_count
        row = {
            **super().row_metrics(episode),
            "imitation_weight": self.imitation_weight(episode),
            "imitation_loss": self.imitation_loss_sum / n if n else math.nan,
            "teacher_agreement": self.agreement_sum / n if n else math.nan,
            "teacher_seconds": self.teacher_seconds,
            "connectivity_loss": (
                self.connectivity_loss_sum / self.connectivity_count
                if self.connectivity_count else math.nan
            ),
        }  # fmt: skip
        self.imitation_loss_sum, self.agreement_sum, self.imitation_count = 0.0, 0.0, 0
        self.connectivity_loss_sum, self.connectivity_count = 0.0, 0
        return row

    def progress(self, episode: int) -> dict[str, str]:
        return {**super().progress(episode), "imit": f"{self.imitation_weight(episode):.2f}"}

    def state_dict(self) -> dict[str, Any]:
        return {
            **super().state_dict(),
            "teacher_seconds": float(self.teacher_seconds),
            "imitation_loss_sum": float(self.imitation_loss_sum),
            "agreement_sum": float(self.agreement_sum),
            "imitation_count": int(self.imitation_count),
            "connectivity_head": (
                None if self.connectivity_head is None else self.connectivity_head.state_dict()
            ),
            "connectivity_loss_sum": float(self.connectivity_loss_sum),
            "connectivity_count": int(self.connectivity_count),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        super().load_state_dict(state)
        self.teacher_seconds = float(state["teacher_seconds"])
        self.imitation_loss_sum = float(state["imitation_loss_sum"])
        self.agreement_sum = float(state["agreement_sum"])
        self.imitation_count = int(state["imitation_count"])
        if self.connectivity_head is not None:
            self.connectivity_head.load_state_dict(state["connectivity_head"])
        # Checkpoints of guided runs from before the connectivity head have no sums.
        self.connectivity_loss_sum = float(state.get("connectivity_loss_sum", 0.0))
        self.connectivity_count = int(state.get("connectivity_count", 0))


__all__ = ["GuidedDQNLearner", "connectivity_loss", "large_margin_loss"]
