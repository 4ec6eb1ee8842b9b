"""An amortised belief over the target's inputs (issue 61): one forward pass per step
where identify-and-plan updates a posterior.

:class:`AmortisedBelief` reads an episode's history so far, neuron by neuron, and says
at every step, for each neuron i, how likely G[i, target] is each of {0, +1, -1} (no
synapse onto the target, an excitatory one, an inhibitory one). Neurons are tokens with
shared weights: a per-neuron GRU over time, then a transformer layer across the neurons
of each step (no positional encoding), so the network runs on any n and permuting the
neurons permutes its outputs. It is causal: step t's output reads steps 0..t only.

What a neuron's token reads at step t is :func:`belief_features`: what the environment
observes (the action, the spikes, the potentials), the target's identity, the
generator's prior for the pair (i, target) by their distance on the line, and the
evidence the neuron model makes of it (docs/model.md): the releases of the step before,
read from the spikes by the vesicle rule, and each neuron's *residual*, what its
synapses added to its potential in units of w_in (:class:`~spikectl.planning.ObservedState`
computes the same for the planner). A neuron that released alone the step before the
target's residual was observed is identified exactly by that residual; the network
learns the rest (releases together, neurons never seen to release) from generated
episodes (``spikectl.training.belief``).

Shapes in comments: B batch, T time, n neurons, F features, D width.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING

FEATURES = (
    "stimulated",
    "spiked",
    "potential",
    "released_before",
    "is_target",
    "prior",
    "target_residual",
    "target_observed",
    "released_times_target_residual",
    "released_while_target_observed",
    "others_released",
    "released_times_others_residual",
    "alone_count",
    "alone_mean_residual",
    "released_count",
    "released_mean_residual",
    "released_mean_others",
)
"""The per-neuron, per-step inputs of :class:`AmortisedBelief`, in column order."""
N_FEATURES = len(FEATURES)
PRIOR_COLUMN = FEATURES.index("prior")
CLASSES = ("none", "excitatory", "inhibitory")
"""The output classes of G[i, target], in logit order."""


class BeliefShapeError(ValueError):
    """The history given to :func:`belief_features` or :class:`AmortisedBelief` has
    inconsistent shapes or values."""


def release_history(spikes: np.ndarray, params: NeuronParams) -> np.ndarray:
    """bool [B, T, n]: which spikes released vesicles (the paper's vesicle rule: at least
    ``min_release_interval_steps`` steps since the neuron's last release; none before
    the episode, whose neurons start rested)."""
    batch, steps, n = spikes.shape
    interval = params.min_release_interval_steps
    since = np.full((batch, n), interval, dtype=np.int64)  # rested: the first spike releases
    released = np.zeros(spikes.shape, dtype=bool)
    for t in range(steps):
        since = np.minimum(since + 1, interval)  # saturates: only ">= interval" matters
        released[:, t] = spikes[:, t] & (since >= interval)
        since[released[:, t]] = 0
    return released


def residuals(
    voltages: np.ndarray, spikes: np.ndarray, actions: np.ndarray, params: NeuronParams
) -> tuple[np.ndarray, np.ndarray]:
    """(residual [B, T, n] in units of w_in, observed [B, T, n] bool): what the synapses
    added to each neuron's potential at step t, where the neuron was not refractory (a
    refractory neuron is held at V_r and shows nothing; ``observed`` False, residual 0)."""
    batch, steps, n = voltages.shape
    v_rest = params.v_rest_mV
    after_reset = np.full((batch, n), v_rest)  # [B, n] V after the previous step's reset
    refractory_left = np.zeros((batch, n), dtype=np.int64)
    residual = np.zeros(voltages.shape)
    observed = np.zeros(voltages.shape, dtype=bool)
    neurons = np.arange(n)
    for t in range(steps):
        stimulus = (actions[:, t, None] == neurons[None, :]) * params.stimulus_step_mV  # [B, n]
        predicted = after_reset + (-(after_reset - v_rest) * params.leak_per_step + stimulus)
        observed[:, t] = refractory_left == 0
        residual[:, t] = np.where(
            observed[:, t], (voltages[:, t] - predicted) / params.synaptic_step_mV, 0.0
        )
        spiked = spikes[:, t]
        after_reset = np.where(spiked | ~observed[:, t], v_rest, voltages[:, t])
        refractory_left = np.where(
            spiked, params.refractory_steps, np.maximum(refractory_left - 1, 0)
        )
    return residual, observed


def belief_features(
    voltages: np.ndarray,
    spikes: np.ndarray,
    actions: np.ndarray,
    targets: np.ndarray,
    params: NeuronParams | None = None,
) -> np.ndarray:
    """float32 [B, T, n, F]: :data:`FEATURES` of each neuron at each step.

    Args:
        voltages: [B, T, n] observed potentials in mV (after integration, before reset).
        spikes: [B, T, n] bool.
        actions: [B, T] neuron indices, -1 for doing nothing (the step's own action).
        targets: [B] the target neuron of each episode.
        params: the neuron model (the paper's when None).
    """
    params = NeuronParams() if params is None else params
    voltages = np.asarray(voltages, dtype=np.float64)
    spikes = np.asarray(spikes, dtype=bool)
    actions = np.asarray(actions)
    targets = np.asarray(targets)
    if voltages.ndim != 3 or spikes.shape != voltages.shape:
        raise BeliefShapeError(
            f"voltages and spikes must both be [B, T, n], got {voltages.shape} and {spikes.shape}"
        )
    batch, steps, n = voltages.shape
    if actions.shape != (batch, steps) or targets.shape != (batch,):
        raise BeliefShapeError(
            f"actions must be [B, T] = {(batch, steps)} and targets [B] = {(batch,)}, "
            f"got {actions.shape} and {targets.shape}"
        )
    if actions.size and (actions.min() < DO_NOTHING or actions.max() >= n):
        raise BeliefShapeError(f"actions must lie in -1..{n - 1}")
    if targets.size and (targets.min() < 0 or targets.max() >= n):
        raise BeliefShapeError(f"targets must be neuron indices in 0..{n - 1}")
    neurons = np.arange(n)
    released = release_history(spikes, params)
    released_before = np.zeros(released.shape)  # [B, T, n]: released at t - 1
    released_before[:, 1:] = released[:, :-1]
    residual, observed = residuals(voltages, spikes, actions, params)
    rows = np.arange(batch)
    target_residual = residual[rows, :, targets][:, :, None]  # [B, T] -> [B, T, 1]
    target_observed = observed[rows, :, targets][:, :, None].astype(np.float64)
    is_target = (neurons[None, :] == targets[:, None]).astype(np.float64)  # [B, n]
    prior = connection_probability(np.abs(neurons[None, :] - targets[:, None]))  # [B, n]
    prior = np.where(is_target > 0, 0.0, prior)
    seen_residual = residual * observed  # [B, T, n]
    others_residual = seen_residual.sum(axis=2, keepdims=True) - seen_residual  # [B, T, n]
    columns = (
        actions[:, :, None] == neurons[None, None, :],
        spikes,
        np.clip((voltages - params.v_rest_mV) / params.synaptic_step_mV, -2.0, 3.0),
        released_before,
        np.broadcast_to(is_target[:, None, :], (batch, steps, n)),
        np.broadcast_to(prior[:, None, :], (batch, steps, n)),
        np.broadcast_to(target_residual * target_observed, (batch, steps, n)),
        np.broadcast_to(target_observed, (batch, steps, n)),
        released_before * target_residual * target_observed,
        released_before * target_observed,
        released_before.sum(axis=2, keepdims=True) - released_before,
        released_before * np.clip(others_residual, -4.0, 4.0),
        *evidence_so_far(released_before, target_residual, target_observed),
    )
    return np.stack(columns, axis=-1).astype(np.float32)  # [B, T, n, F]


def evidence_so_far(
    released_before: np.ndarray, target_residual: np.ndarray, target_observed: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Running sums over steps 0..t of the target's evidence about each neuron, each
    [B, T, n]: (how often it released *alone* while the target was observed, capped at
    3, and the target's mean residual then: exactly G[i, target] once that count is 1;
    the same over every release of i, and the mean number of others that released with
    it). Sums, so a controller keeps them in O(n) a step; they spare the network from
    learning to count."""
    others = released_before.sum(axis=2, keepdims=True) - released_before  # [B, T, n]
    seen = released_before * target_observed  # [B, T, n]: i's release, target observed
    alone = seen * (others == 0)  # [B, T, n]
    alone_count = np.cumsum(alone, axis=1)  # [B, T, n]
    alone_sum = np.cumsum(alone * target_residual, axis=1)  # [B, T, n]
    count = np.cumsum(seen, axis=1)  # [B, T, n]
    residual_sum = np.cumsum(seen * target_residual, axis=1)  # [B, T, n]
    others_sum = np.cumsum(seen * others, axis=1)  # [B, T, n]
    return (
        np.minimum(alone_count, 3.0) / 3.0,
        np.clip(alone_sum / np.maximum(alone_count, 1.0), -2.0, 2.0),
        np.minimum(count, 5.0) / 5.0,
        np.clip(residual_sum / np.maximum(count, 1.0), -4.0, 4.0),
        np.minimum(others_sum / np.maximum(count, 1.0), 8.0) / 8.0,
    )


def prior_logits(features: torch.Tensor) -> torch.Tensor:
    """[..., n, F] → [..., n, 3]: the log-probabilities of :data:`CLASSES` under the
    generator's prior (the ``prior`` column: a connection with its distance's
    probability p, excitatory with probability 0.8), clipped away from 0 and 1."""
    p = features[..., PRIOR_COLUMN].clamp(1e-4, 1.0 - 1e-4)  # [..., n]
    excitatory = EXCITATORY_PROBABILITY
    return torch.stack(
        [torch.log1p(-p), torch.log(p * excitatory), torch.log(p * (1.0 - excitatory))], dim=-1
    )  # [..., n, 3]


class AmortisedBelief(nn.Module):
    """Per-neuron GRU over time → transformer layer across neurons → 3 logits per neuron,
    added to the prior's (:func:`prior_logits`).

    ``forward(features [B, T, n, F])`` → logits [B, T, n, 3] over :data:`CLASSES`; the
    target's own row is meaningless (it has no synapse onto itself) and is masked by
    :meth:`synapse_probability`. ``step`` runs one step with a carried GRU state, for a
    controller that decides step by step.
    """

    def __init__(self, width: int = 48, heads: int = 4, mix_layers: int = 1) -> None:
        super().__init__()
        if width < 1 or heads < 1 or width % heads or mix_layers < 0:
            raise ValueError(
                f"width ({width}) must be a positive multiple of heads ({heads}) and "
                f"mix_layers ({mix_layers}) >= 0"
            )
        self.width, self.heads, self.mix_layers = width, heads, mix_layers
        self.encode = nn.Sequential(
            nn.Linear(N_FEATURES, width), nn.GELU(), nn.Linear(width, width), nn.GELU()
        )
        self.memory = nn.GRU(width, width, batch_first=True)
        self.mix = nn.ModuleList(
            nn.TransformerEncoderLayer(
                width, heads, dim_feedforward=2 * width, dropout=0.0, batch_first=True
            )
            for _ in range(mix_layers)
        )
        self.head = nn.Sequential(nn.Linear(2 * width, width), nn.GELU(), nn.Linear(width, 3))
        # The head says how the evidence moves the base rate: zero at the start, so an
        # untrained belief is the generator's prior.
        nn.init.zeros_(self.head[-1].weight)
        nn.init.zeros_(self.head[-1].bias)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """[B, T, n, F] → logits [B, T, n, 3]."""
        batch, steps, n, _ = self._check(features)
        encoded = self.encode(features)  # [B, T, n, D]
        sequences = encoded.permute(0, 2, 1, 3).reshape(batch * n, steps, self.width)
        memory, _ = self.memory(sequences)  # [B*n, T, D]
        memory = memory.reshape(batch, n, steps, self.width).permute(0, 2, 1, 3)  # [B, T, n, D]
        evidence = self._decide(memory.reshape(batch * steps, n, self.width))  # [B*T, n, 3]
        return evidence.reshape(batch, steps, n, 3) + prior_logits(features)  # [B, T, n, 3]

    def step(
        self, features: torch.Tensor, state: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One step: features [B, n, F], GRU state [1, B*n, D] or None (episode start) →
        (logits [B, n, 3], the new state). Equal to :meth:`forward` step by step."""
        batch, _, n, _ = self._check(features[:, None])  # [B, n, F] -> [B, 1, n, F]
        encoded = self.encode(features).reshape(batch * n, 1, self.width)  # [B*n, 1, D]
        memory, state = self.memory(encoded, state)  # [B*n, 1, D], [1, B*n, D]
        logits = self._decide(memory.reshape(batch, n, self.width))  # [B, n, 3]
        return logits + prior_logits(features), state

    def _decide(self, memory: torch.Tensor) -> torch.Tensor:
        """[S, n, D] per-neuron memories of S (episode, step) pairs → logits [S, n, 3]."""
        mixed = memory
        for layer in self.mix:
            mixed = layer(mixed)  # [S, n, D]: attention across the step's neurons
        return self.head(torch.cat([memory, mixed], dim=-1))  # [S, n, 2D] -> [S, n, 3]

    @staticmethod
    def _check(features: torch.Tensor) -> tuple[int, int, int, int]:
        if features.ndim != 4 or features.shape[-1] != N_FEATURES:
            raise BeliefShapeError(
                f"features must be [B, T, n, {N_FEATURES}], got {tuple(features.shape)}"
            )
        return tuple(features.shape)

    @staticmethod
    def synapse_probability(logits: torch.Tensor, is_target: torch.Tensor) -> torch.Tensor:
        """[..., n] P(G[i, target] != 0) from logits [..., n, 3]; 0 for the target itself
        (``is_target`` [..., n] bool)."""
        probability = 1.0 - torch.softmax(logits, dim=-1)[..., 0]  # [..., n]
        return torch.where(is_target, torch.zeros_like(probability), probability)

    @staticmethod
    def excitation_probability(logits: torch.Tensor, is_target: torch.Tensor) -> torch.Tensor:
        """[..., n] P(G[i, target] = +1) from logits [..., n, 3] (what the planner reads
        of a belief: which neurons can drive the target); 0 for the target itself."""
        probability = torch.softmax(logits, dim=-1)[..., 1]  # [..., n]
        return torch.where(is_target, torch.zeros_like(probability), probability)
