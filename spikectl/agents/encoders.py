"""The encoders the four networks are built from (paper App. C): the MLP, the context
encoder, the per-neuron LSTM and the transformer mixer across neurons.

Shapes in comments: B batch, T time, n neurons, N episode length, F per-neuron input
features, H LSTM width, W attention width, E / P target / pattern code widths,
C context width (E + P).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch
from torch import nn

from spikectl.agents.features import neuron_indicator, shift_pattern


class MLP(nn.Sequential):
    """Linear + ReLU for each hidden width, then a plain Linear to ``out_features``.

    With ``out_features=None`` it ends with the last hidden ReLU. ``layer_norm=True``
    puts a LayerNorm between each hidden Linear and its ReLU (what keeps Q-learning
    without a target network stable, PQN); off, the layers and their saved names are
    the paper's. A LayerNorm draws nothing at initialisation, so the Linears start the
    same either way.
    """

    def __init__(
        self,
        in_features: int,
        hidden: Sequence[int],
        out_features: int | None,
        layer_norm: bool = False,
    ) -> None:
        layers: list[nn.Module] = []
        width = in_features
        for h in hidden:
            layers += [nn.Linear(width, h), *([nn.LayerNorm(h)] if layer_norm else []), nn.ReLU()]
            width = h
        if out_features is not None:
            layers.append(nn.Linear(width, out_features))
            width = out_features
        super().__init__(*layers)
        self.out_features = width


class ContextEncoder(nn.Module):
    """Observable context: target → FF+ReLU → 16, shifted pattern → FF+ReLU → 16.

    ``n_neurons=None`` (per-neuron architectures): the target enters as a
    per-neuron indicator, output [B, T, n, C] with the pattern code repeated for
    every neuron; permutation equivariant and valid for any n.
    ``n_neurons=n`` (DRQN, DMDRQN): the target enters one-hot over n, output [B, T, C].
    """

    def __init__(
        self, episode_length: int, target_embed: int, pattern_embed: int, n_neurons: int | None
    ) -> None:
        super().__init__()
        self.n_neurons = n_neurons
        self.target = nn.Sequential(nn.Linear(n_neurons or 1, target_embed), nn.ReLU())
        self.pattern = nn.Sequential(nn.Linear(episode_length, pattern_embed), nn.ReLU())
        self.out_features = target_embed + pattern_embed

    def encode_pattern(self, pattern: torch.Tensor, step: torch.Tensor) -> torch.Tensor:
        """pattern [..., N], step [...] → [..., pattern_embed]."""
        dtype = self.pattern[0].weight.dtype
        return self.pattern(shift_pattern(pattern, step, dtype))  # [..., P]

    def forward(self, obs: Mapping[str, torch.Tensor], n: int) -> torch.Tensor:
        dtype = self.pattern[0].weight.dtype
        pattern_code = self.encode_pattern(obs["pattern"], obs["step"])  # [B, T, P]
        if self.n_neurons is None:
            indicator = neuron_indicator(obs["target"], n, dtype).unsqueeze(-1)  # [B, T, n, 1]
            target_code = self.target(indicator)  # [B, T, n, E]
            pattern_code = pattern_code.unsqueeze(-2).expand(*target_code.shape[:-1], -1)
            # pattern_code: [B, T, n, P]
        else:
            target_code = self.target(neuron_indicator(obs["target"], n, dtype))  # [B, T, E]
        return torch.cat([target_code, pattern_code], dim=-1)  # [B, T, (n,) C]


class PerNeuronLSTM(nn.Module):
    """One LSTM (one set of weights) with a separate hidden state per neuron.

    The neurons are folded into the batch: [B, T, n, F] → [B*n, T, F]. The state
    is (h, c), each [B, n, H]; it works for any n.
    """

    def __init__(self, in_features: int, hidden: int) -> None:
        super().__init__()
        self.hidden = hidden
        self.lstm = nn.LSTM(in_features, hidden, batch_first=True)

    def forward(
        self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor]
    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        B, T, n, F_ = x.shape
        H = self.hidden
        x = x.permute(0, 2, 1, 3).reshape(B * n, T, F_)  # [B*n, T, F]
        h0 = state[0].reshape(1, B * n, H)  # [1, B*n, H]
        c0 = state[1].reshape(1, B * n, H)  # [1, B*n, H]
        y, (h, c) = self.lstm(x, (h0.contiguous(), c0.contiguous()))  # y: [B*n, T, H]
        y = y.reshape(B, n, T, H).permute(0, 2, 1, 3)  # [B, T, n, H]
        return y, (h.reshape(B, n, H), c.reshape(B, n, H))  # state: [B, n, H] each


class NeuronMixer(nn.Module):
    """Transformer encoder across the n neuron tokens, independently at each step.

    No positional encoding, so it is permutation equivariant over neurons and
    valid for any n. Post-norm encoder layers (Vaswani et al.), ReLU, no dropout.
    """

    def __init__(self, in_features: int, width: int, layers: int, heads: int, ff: int) -> None:
        super().__init__()
        self.project = nn.Linear(in_features, width) if in_features != width else nn.Identity()
        layer = nn.TransformerEncoderLayer(
            d_model=width, nhead=heads, dim_feedforward=ff, dropout=0.0, batch_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.out_features = width

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        B, T, n, _ = x.shape
        x = self.project(x)  # [B, T, n, W]
        x = x.reshape(B * T, n, -1)  # [B*T, n, W]
        x = self.encoder(x)  # [B*T, n, W]
        return x.reshape(B, T, n, -1)  # [B, T, n, W]
