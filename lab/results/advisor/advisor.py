"""ADVISOR (Weihs et al. 2021, "Bridging the imitation gap by adaptive insubordination")
on the guided learner: imitate the teacher only on the steps where a head trained to
imitate it alone can, and leave the rest to the TD loss (issue 44, item 4).

An auxiliary policy head, the same shape as the network's Q head (a fresh copy of it, on
the same features and per-neuron context), is trained by cross-entropy on the teacher's
labels. At each labelled step its cross-entropy CE_aux(h) says how well the teacher's
action can be read from what the student has seen; the imitation loss of that step is
weighted by

    w(h) = exp(-alpha * CE_aux(h))          (no gradient through w)

so that where the teacher acts on what the history does not show (a teacher told the
weights, or a choice the features cannot represent) the student is left to reward.
The TD loss is kept at every step (DQfD's form; ADVISOR's (1 - w) weighting of the RL
loss would leave Q-learning without its bootstraps where w is near 1).

    python lab/results/advisor/advisor.py RUN_DIR SEED ALPHA TEACHER IMITATION_END

runs the README's main job (``spikectl train guided``) with this learner, the teacher
``identify`` or ``told-weights`` and the imitation weight annealed from 1 to
IMITATION_END. A research script: the library is unchanged; config.json names the
learner ``guided-advisor`` and records ``advisor_alpha``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import sys
from dataclasses import dataclass
from typing import Any, ClassVar

import torch

from spikectl.agents import masked_q
from spikectl.agents.observation import long_indices
from spikectl.seeds import torch_seed
from spikectl.training.learners.dqn_losses import (
    batch_tensors,
    connectivity_loss,
    losses_on_tensors,
)
from spikectl.training.learners.guided import GuidedDQNLearner
from spikectl.training.learners.guided_config import GuidedConfig
from spikectl.training.learners.registry import register
from spikectl.training.presets import PRESETS
from spikectl.training.run import train

ADVISOR_HEAD_STREAM = 1044
"""The auxiliary policy head's initialisation stream (a number of this script's own)."""


@dataclass(frozen=True)
class AdvisorConfig(GuidedConfig):
    """The guided learner with ADVISOR's per-step imitation weight."""

    name: ClassVar[str] = "guided-advisor"
    advisor_alpha: float = 4.0
    """alpha in w(h) = exp(-alpha * CE_aux(h)); 0 gives every labelled step weight 1."""


def per_step_large_margin(
    q_values: torch.Tensor, index: torch.Tensor, legal: torch.Tensor, margin: float
) -> torch.Tensor:
    """DQfD's large-margin loss at each step: q_values [B, N, n+1], index [B, N] (the
    teacher's action + 1, clamped), legal [B, 1, n+1] → [B, N]."""
    margins = torch.full_like(q_values, margin).scatter(2, index[..., None], 0.0)
    best_with_margin = masked_q(q_values + margins, legal).max(dim=2).values  # [B, N]
    return best_with_margin - q_values.gather(2, index[..., None]).squeeze(2)


class AdvisorLearner(GuidedDQNLearner):
    metric_fields = GuidedDQNLearner.metric_fields + ("advisor_weight", "aux_policy_ce")

    def __init__(self, config, train_set, rng) -> None:
        super().__init__(config, train_set, rng)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(torch_seed(config.train.seed, ADVISOR_HEAD_STREAM))
            self.policy_head = copy.deepcopy(self.network.head)
            for module in self.policy_head.modules():
                if hasattr(module, "reset_parameters"):
                    module.reset_parameters()
        self.policy_head.to(self.device)
        self.optimizer.add_param_group({"params": list(self.policy_head.parameters())})
        self.weight_sum, self.ce_sum, self.advisor_count = 0.0, 0.0, 0

    def batch_loss(self, batch, episode: int) -> torch.Tensor:
        weight = self.imitation_weight(episode)
        if weight <= 0:
            return super().batch_loss(batch, episode)
        tensors = batch_tensors(batch, self.device)
        td, aux, q_values, features = losses_on_tensors(
            self.network, self.target, tensors, self.settings, self.predictor, True, True
        )
        loss = self.td_and_aux_loss(td, aux)
        if self.connectivity_head is not None:
            target_inputs = torch.as_tensor(batch.target_inputs, device=self.device)  # [B, n]
            connectivity = connectivity_loss(self.connectivity_head, features, target_inputs)
            self.connectivity_loss_sum += connectivity.item()
            self.connectivity_count += 1
            loss = loss + self.settings.connectivity_weight * connectivity
        labels = torch.as_tensor(batch.labels, device=self.device)  # [B, N]
        legal = tensors["legal"]  # [B, 1, n+1]
        labelled = labels >= -1  # [B, N]
        count = labelled.sum()
        if count == 0:
            return loss
        index = labels.clamp(min=-1) + 1  # [B, N]
        # The auxiliary policy: the Q head's shape on the same features and context.
        obs = long_indices(tensors["obs_seq"])
        step_features = features[:, :-1]  # [B, N, n, D]
        context = self.network.context(
            {key: value[:, :-1] for key, value in obs.items()}, step_features.shape[-2]
        )  # [B, N, n, C]
        logits = self.policy_head(
            torch.cat([step_features, context], dim=-1), obs["target"][:, :-1]
        )  # [B, N, n+1]
        log_policy = torch.log_softmax(masked_q(logits, legal), dim=2)  # [B, N, n+1]
        ce = -log_policy.gather(2, index[..., None]).squeeze(2)  # [B, N]
        advisor = torch.exp(-self.settings.advisor_alpha * ce.detach())  # [B, N]
        margin_loss = per_step_large_margin(
            q_values[:, :-1], index, legal, self.settings.imitation_margin
        )  # [B, N]
        imitation = (advisor * margin_loss * labelled).sum() / count
        ce_loss = (ce * labelled).sum() / count
        with torch.no_grad():
            greedy = masked_q(q_values[:, :-1], legal).argmax(dim=2)  # [B, N]
            agreement = ((greedy == index) & labelled).sum() / count
        self.imitation_loss_sum += imitation.item()
        self.agreement_sum += agreement.item()
        self.imitation_count += 1
        self.weight_sum += ((advisor * labelled).sum() / count).item()
        self.ce_sum += ce_loss.item()
        self.advisor_count += 1
        return loss + weight * imitation + ce_loss

    def row_metrics(self, episode: int) -> dict[str, float]:
        n = self.advisor_count
        row = {
            **super().row_metrics(episode),
            "advisor_weight": self.weight_sum / n if n else math.nan,
            "aux_policy_ce": self.ce_sum / n if n else math.nan,
        }
        self.weight_sum, self.ce_sum, self.advisor_count = 0.0, 0.0, 0
        return row

    def state_dict(self) -> dict[str, Any]:
        return {**super().state_dict(), "policy_head": self.policy_head.state_dict()}

    def load_state_dict(self, state) -> None:
        super().load_state_dict(state)
        self.policy_head.load_state_dict(state["policy_head"])


def experiment(seed: int, alpha: float, teacher: str, imitation_end: float):
    """The README's main job with the ADVISOR learner (registered here, not at import:
    registering the same entry again is a no-op)."""
    register(AdvisorConfig, AdvisorLearner)
    guided = PRESETS["guided"]
    learner = AdvisorConfig(
        **{**dataclasses.asdict(guided.learner), "teacher": teacher,
           "imitation_weight_end": imitation_end},
        advisor_alpha=alpha,
    )  # fmt: skip
    run = dataclasses.replace(guided.train, progress=False)
    return dataclasses.replace(guided, train=run, learner=learner).with_seed(seed)


if __name__ == "__main__":
    run_dir, seed, alpha, teacher, end = sys.argv[1:6]
    torch.set_num_threads(1)
    train(experiment(int(seed), float(alpha), teacher, float(end)), run_dir)
