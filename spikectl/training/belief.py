"""Training and measuring the amortised belief (issue 61) by supervised learning.

:func:`train_belief` is a function of a typed config (:class:`BeliefTrainingConfig`)
that returns the trained :class:`~spikectl.agents.amortised_belief.AmortisedBelief`
and its metrics rows: every update draws a fresh batch of labelled episodes
(:func:`~spikectl.training.belief_episodes.belief_batch`) of a size drawn from
``sizes`` and takes one Adam step on the cross-entropy of G[i, target]'s class, over
every step of every episode and every neuron but the target. All randomness comes from
``seed``: the episodes from ``default_rng([seed, 0])``, the initialisation from Torch
under ``torch_seed(seed, 1)`` (the global Torch generator is left as it was).

:func:`belief_scores` measures a belief on a batch: the binary cross-entropy of "i has
a synapse onto the target" after k steps, against the base rate (the generator's prior
by distance, what is known with no evidence).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn

from spikectl.agents.amortised_belief import AmortisedBelief
from spikectl.seeds import torch_seed
from spikectl.training.belief_episodes import BehaviourMix, BeliefBatch, belief_batch

EPISODE_STREAM = 0
"""Under the belief's training seed: the training episodes' generator."""
INIT_STREAM = 1
"""Under the belief's training seed: the network's Torch initialisation."""
PROBABILITY_FLOOR = 1e-6
"""Probabilities are clipped to [floor, 1 - floor] before a logarithm."""


@dataclass(frozen=True)
class BeliefTrainingConfig:
    """What :func:`train_belief` trains: the network, the episodes, the optimiser."""

    seed: int = 0
    sizes: tuple[int, ...] = (8, 12, 16, 24, 32)
    episode_length: int = 60
    batch: int = 16
    """Episodes per update (all of one size)."""
    updates: int = 2000
    learning_rate: float = 2e-3
    final_learning_rate: float = 2e-4
    """Cosine decay to this at the last update."""
    width: int = 48
    heads: int = 4
    mix_layers: int = 1
    behaviour: BehaviourMix = field(default_factory=BehaviourMix)
    log_every: int = 100
    """Updates between metrics rows (the mean training loss since the last row)."""

    def __post_init__(self) -> None:
        if not self.sizes or any(not isinstance(n, int) or n < 2 for n in self.sizes):
            raise ValueError(f"BeliefTrainingConfig.sizes must be integers >= 2, got {self.sizes}")
        for name in ("episode_length", "batch", "updates", "log_every"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"BeliefTrainingConfig.{name} must be a positive integer, "
                                 f"got {value!r}")  # fmt: skip
        if not 0 < self.final_learning_rate <= self.learning_rate:
            raise ValueError(
                "BeliefTrainingConfig needs 0 < final_learning_rate <= learning_rate, got "
                f"{self.final_learning_rate}, {self.learning_rate}"
            )

    def to_dict(self) -> dict:
        """The config as JSON-ready values."""
        values = asdict(self)
        values["sizes"] = list(self.sizes)
        values["behaviour"]["stretch_steps"] = list(self.behaviour.stretch_steps)
        return values


def make_belief(config: BeliefTrainingConfig) -> AmortisedBelief:
    """The untrained network of ``config``, initialised from its seed."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(torch_seed(config.seed, INIT_STREAM))
        return AmortisedBelief(config.width, config.heads, config.mix_layers)


def tensors(batch: BeliefBatch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(features [B, T, n, F], labels [B, n], is_target [B, n]) as Torch tensors."""
    return (
        torch.from_numpy(batch.features),
        torch.from_numpy(batch.labels),
        torch.from_numpy(batch.is_target),
    )


def belief_loss(
    logits: torch.Tensor, labels: torch.Tensor, is_target: torch.Tensor
) -> torch.Tensor:
    """Mean cross-entropy of logits [B, T, n, 3] against labels [B, n] over every step
    and every neuron but the target."""
    steps = logits.shape[1]
    expanded = labels[:, None, :].expand(-1, steps, -1)  # [B, n] -> [B, T, n]
    losses = nn.functional.cross_entropy(
        logits.reshape(-1, 3), expanded.reshape(-1), reduction="none"
    ).reshape(expanded.shape)  # [B*T*n] -> [B, T, n]
    keep = (~is_target)[:, None, :].expand_as(losses).to(losses.dtype)  # [B, T, n]
    return (losses * keep).sum() / keep.sum()


def train_belief(config: BeliefTrainingConfig) -> tuple[AmortisedBelief, list[dict]]:
    """Train the belief of ``config``; (the network, its metrics rows)."""
    model = make_belief(config)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    rng = np.random.default_rng([config.seed, EPISODE_STREAM])
    rows: list[dict] = []
    running, count, started = 0.0, 0, time.process_time()
    for update in range(1, config.updates + 1):
        progress = (update - 1) / max(config.updates - 1, 1)
        rate = config.final_learning_rate + 0.5 * (
            config.learning_rate - config.final_learning_rate
        ) * (1.0 + np.cos(np.pi * progress))
        for group in optimiser.param_groups:
            group["lr"] = rate
        n_neurons = int(rng.choice(config.sizes))
        batch = belief_batch(rng, n_neurons, config.batch, config.episode_length, config.behaviour)
        features, labels, is_target = tensors(batch)
        loss = belief_loss(model(features), labels, is_target)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        running, count = running + loss.item(), count + 1
        if update % config.log_every == 0 or update == config.updates:
            rows.append({
                "update": update,
                "train_loss": running / count,
                "learning_rate": float(rate),
                "cpu_seconds": time.process_time() - started,
            })  # fmt: skip
            running, count = 0.0, 0
    return model, rows


def binary_cross_entropy(probability: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Elementwise -log P(truth) for P(true) = ``probability``, clipped away from 0 and 1."""
    probability = np.clip(probability, PROBABILITY_FLOOR, 1.0 - PROBABILITY_FLOOR)
    return -np.where(truth, np.log(probability), np.log1p(-probability))


def synapse_probabilities(model: AmortisedBelief, batch: BeliefBatch) -> np.ndarray:
    """float64 [B, T, n]: the belief's P(G[i, target] != 0) after each step."""
    features, _, is_target = tensors(batch)
    with torch.no_grad():
        logits = model(features)  # [B, T, n, 3]
        probability = model.synapse_probability(logits, is_target[:, None, :])
    return probability.double().numpy()


def belief_scores(
    probability: np.ndarray, batch: BeliefBatch, after_steps: tuple[int, ...]
) -> list[dict]:
    """Rows {after_steps, cross_entropy, base_rate_cross_entropy, removed}: the mean
    binary cross-entropy (nats per neuron, the target excluded) of ``probability``
    [B, T, n] after k steps (its row k - 1) against the truth, the same of the base rate,
    and the fraction of the base rate's cross-entropy removed."""
    truth = batch.labels > 0  # [B, n]
    keep = ~batch.is_target  # [B, n]
    base = binary_cross_entropy(batch.prior, truth)[keep].mean()
    rows = []
    for steps in after_steps:
        if not 1 <= steps <= probability.shape[1]:
            raise ValueError(f"after_steps must lie in 1..{probability.shape[1]}, got {steps}")
        entropy = binary_cross_entropy(probability[:, steps - 1], truth)[keep].mean()
        rows.append({
            "after_steps": steps,
            "cross_entropy": float(entropy),
            "base_rate_cross_entropy": float(base),
            "removed": float(1.0 - entropy / base),
        })  # fmt: skip
    return rows
