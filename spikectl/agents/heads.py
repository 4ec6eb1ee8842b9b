"""What the networks' features are read by: the per-neuron Q head, the auxiliary
next-voltage predictor, and the masking and argmax that turn Q-values into actions.

Q-value vectors have n + 1 entries ordered by ``action + 1``: index 0 = do nothing,
index j + 1 = stimulate neuron j. Shapes in comments: B batch, T time, n neurons,
U per-neuron head input width, D feature width.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from spikectl.agents.encoders import MLP
from spikectl.agents.features import action_one_hot, neuron_indicator


class PerNeuronQHead(nn.Module):
    """Per-neuron Q-values plus a permutation-invariant "do nothing" value.

    Input u [B, T, n, U] (each neuron's embedding with its context) and the
    target [B, T]. Each neuron's u goes through the same MLP → one scalar a_i.
    The do-nothing value comes from the pooled, permutation-invariant summary
    ``[mean_i u_i, u_target]`` → MLP → one scalar v. With ``mode="dueling"``
    Q(nothing) = v and Q(stimulate i) = v + a_i; with ``mode="pooled"``
    Q(nothing) = v and Q(stimulate i) = a_i. Output [B, T, n+1] in action+1 order.
    """

    MODES = ("dueling", "pooled")

    def __init__(
        self,
        in_features: int,
        hidden: Sequence[int],
        value_hidden: Sequence[int],
        mode: str,
        layer_norm: bool = False,
    ) -> None:
        super().__init__()
        if mode not in self.MODES:
            raise ValueError(f"do-nothing head mode must be one of {self.MODES}, got {mode!r}")
        self.mode = mode
        self.advantage = MLP(in_features, hidden, 1, layer_norm)
        self.value = MLP(2 * in_features, value_hidden, 1, layer_norm)

    def forward(self, u: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        a = self.advantage(u).squeeze(-1)  # [B, T, n]
        index = target[..., None, None].expand(*u.shape[:-2], 1, u.shape[-1])  # [B, T, 1, U]
        u_target = torch.gather(u, -2, index).squeeze(-2)  # [B, T, U]
        pooled = torch.cat([u.mean(dim=-2), u_target], dim=-1)  # [B, T, 2U]
        v = self.value(pooled)  # [B, T, 1]
        if self.mode == "dueling":
            a = a + v  # [B, T, n]
        return torch.cat([v, a], dim=-1)  # [B, T, n+1]


class NextVoltagePredictor(nn.Module):
    """Auxiliary head: every neuron's next normalised voltage from the features at t and
    the action taken at t (not in the paper; the trainer's ``aux_voltage_weight``).

    In the noise-free model a neuron's next voltage is its leaky step plus ±20 mV per
    released presynaptic spike plus 40 mV if stimulated, so predicting it asks the
    encoder to learn the hidden connectivity the Q-values need.

    ``n_neurons=None`` (per-neuron features [B, T, n, M], DDRQN and TDRQN): one shared
    MLP per neuron on [features, stimulated at t] → [B, T, n]. ``n_neurons=n`` (system
    features [B, T, D], DRQN and DMDRQN): MLP on [features, one-hot action] → [B, T, n].
    """

    def __init__(self, feature_width: int, n_neurons: int | None, hidden: int = 64) -> None:
        super().__init__()
        self.n_neurons = n_neurons
        if n_neurons is None:
            self.mlp = MLP(feature_width + 1, [hidden], 1)
        else:
            self.mlp = MLP(feature_width + n_neurons + 1, [hidden], n_neurons)

    def forward(self, features: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """features [B, T, (n,) D], actions [B, T] (-1..n-1) → predictions [B, T, n]."""
        dtype = features.dtype
        if self.n_neurons is None:
            n = features.shape[-2]
            stimulated = neuron_indicator(actions, n, dtype).unsqueeze(-1)  # [B, T, n, 1]
            x = torch.cat([features, stimulated], dim=-1)  # [B, T, n, D+1]
            return self.mlp(x).squeeze(-1)  # [B, T, n]
        x = torch.cat([features, action_one_hot(actions, self.n_neurons, dtype)], dim=-1)
        return self.mlp(x)  # [B, T, n]


class ConnectivityPredictor(nn.Module):
    """Auxiliary head: each observed neuron's synapse onto the target (inhibitory, none,
    excitatory) from the features at t (not in the paper; the guided learner's
    ``connectivity_weight``).

    Whether stimulating neuron i can make the target spike is the sign of its synapse
    onto the target, so asking every step's features to say it asks the encoder to
    identify, and to keep until the episode ends, what the Q-values of stimulating i
    need. The labels come from the training networks' weights: privileged information
    that only the training loss reads; the controller never sees it.

    ``n_neurons=None`` (per-neuron features [B, T, n, D], DDRQN and TDRQN): one shared
    MLP per neuron → [B, T, n, 3]. ``n_neurons=n`` (system features [B, T, D], DRQN and
    DMDRQN): MLP → [B, T, n, 3]. Logits ordered inhibitory, none, excitatory.
    """

    CLASSES = 3

    def __init__(self, feature_width: int, n_neurons: int | None, hidden: int = 64) -> None:
        super().__init__()
        self.n_neurons = n_neurons
        outputs = self.CLASSES * (1 if n_neurons is None else n_neurons)
        self.mlp = MLP(feature_width, [hidden], outputs)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """features [B, T, (n,) D] → logits [B, T, n, 3]."""
        logits = self.mlp(features)  # [B, T, n, 3] or [B, T, 3n]
        if self.n_neurons is None:
            return logits
        return logits.unflatten(-1, (self.n_neurons, self.CLASSES))  # [B, T, n, 3]


def masked_q(
    q: torch.Tensor, action_mask: torch.Tensor, fill: float = float("-inf")
) -> torch.Tensor:
    """Set the Q-values of illegal actions to ``fill`` (default -inf).

    q [..., n+1] and action_mask bool or int8 [..., n+1] (True / 1 = legal; int8 is what
    the environments' ``info["action_mask"]`` holds) in action+1 order; the mask
    broadcasts against q (e.g. a [B, n+1] mask over q [B, T, n+1] needs
    ``mask[:, None]``). Use before argmax for acting and for double-Q targets.
    """
    if action_mask.dtype == torch.int8:
        action_mask = action_mask != 0
    elif action_mask.dtype != torch.bool:
        raise TypeError(
            "masked_q: action_mask must be bool or int8 (True / 1 = legal), got "
            f"{action_mask.dtype}"
        )
    if action_mask.shape[-1] != q.shape[-1]:
        raise ValueError(
            f"masked_q: action_mask has {action_mask.shape[-1]} actions, q has {q.shape[-1]} "
            "(both are n+1: do nothing first, then one per neuron)"
        )
    return q.masked_fill(~action_mask, fill)


def greedy_action(q: torch.Tensor, action_mask: torch.Tensor | None = None) -> torch.Tensor:
    """Greedy environment action (-1 = do nothing, j = stimulate j) from q [..., n+1]."""
    if action_mask is not None:
        q = masked_q(q, action_mask)
    return q.argmax(dim=-1) - 1  # [...]
