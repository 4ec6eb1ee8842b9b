"""The networks that compute one Q-value per neuron with shared weights, and so run on
any n and are permutation equivariant: DDRQN and TDRQN (paper Section 5.2, App. C, D).

Both are :class:`PerNeuronQNetwork`: per-neuron LSTM → mixing block → per-neuron
context → :class:`~spikectl.agents.heads.PerNeuronQHead`. They differ only in the mixing
block (DDRQN: a per-neuron FF layer, no mixing; TDRQN: a transformer across neurons) and
in the head widths. Shapes in comments: B batch, T time, n neurons, H LSTM width,
M mixing block output width, C context width.
"""

from __future__ import annotations

import torch
from torch import nn

from spikectl.agents.encoders import MLP, ContextEncoder, NeuronMixer
from spikectl.agents.heads import PerNeuronQHead
from spikectl.agents.observation import long_indices
from spikectl.agents.recurrent import Observation, PerNeuronMemory, State


class PerNeuronQNetwork(PerNeuronMemory):
    """Per-neuron LSTM → mixing block → per-neuron Q-values; any n, equivariant.

    per neuron: [v_norm, stimulated, the features of ``sizes.inputs``] → LSTM (H) → mixing
    block ([B, T, n, H] → [B, T, n, M]) ⊕ per-neuron context (C) → PerNeuronQHead
    (:meth:`head_hidden`). Subclasses name the block (:meth:`build_mix`) and the head
    widths. State (h, c), each [B, n, H].
    """

    equivariant = True
    mix_name: str
    """The mixing block's attribute (``ff``, ``mixer``): the prefix of its saved weights'
    keys, so it stays what DDRQN and TDRQN always called it."""

    def build_mix(self) -> nn.Module:
        """The mixing block, [B, T, n, H] → [B, T, n, M]."""
        raise NotImplementedError

    def head_hidden(self) -> tuple[int, ...]:
        """The hidden widths of the per-neuron Q head."""
        raise NotImplementedError

    def build(self) -> None:
        s = self.sizes
        self.lstm = self.build_lstm()
        self.add_module(self.mix_name, self.build_mix())
        self.context = ContextEncoder(self.episode_length, s.target_embed, s.pattern_embed, None)
        self.head = PerNeuronQHead(
            self.mix.out_features + self.context.out_features,
            self.head_hidden(),
            s.value_hidden,
            s.do_nothing_head,
            s.layer_norm,
        )
        self.feature_width = self.mix.out_features
        """Width of :meth:`encode`'s per-neuron output."""

    @property
    def mix(self) -> nn.Module:
        """The mixing block, [B, T, n, H] → [B, T, n, M]."""
        return self.get_submodule(self.mix_name)

    def encode(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """Per-neuron embeddings [B, T, n, M] before the context and the head."""
        y, state = self.lstm_outputs(obs_seq, state)  # [B, T, n, H]
        return self.mix(y), state  # [B, T, n, M]

    def q_values(self, features: torch.Tensor, obs_seq: Observation) -> torch.Tensor:
        """Features [B, T, n, M] from :meth:`encode` → Q-values [B, T, n+1]."""
        obs_seq = long_indices(obs_seq)
        context = self.context(obs_seq, features.shape[-2])  # [B, T, n, C]
        u = torch.cat([features, context], dim=-1)  # [B, T, n, M+C]
        return self.head(u, obs_seq["target"])  # [B, T, n+1]


class DDRQN(PerNeuronQNetwork):
    """Distributed DRQN: shared per-neuron LSTM → per-neuron FF; any n, equivariant.

    per neuron: [v_norm, stimulated, ``sizes.inputs``] → LSTM (H) → FF ff_hidden + ReLU
    ⊕ per-neuron context (C) → PerNeuronQHead (head_hidden). No mixing between
    neurons except the pooled do-nothing value. State (h, c), each [B, n, H].
    """

    mix_name = "ff"

    def build_mix(self) -> nn.Module:
        """DDRQN's mixing block: one feed-forward layer per neuron, no mixing across neurons."""
        return MLP(self.sizes.lstm_hidden, [self.sizes.ff_hidden], None, self.sizes.layer_norm)

    def head_hidden(self) -> tuple[int, ...]:
        """DDRQN's per-neuron Q head widths (``sizes.head_hidden``)."""
        return self.sizes.head_hidden


class TDRQN(PerNeuronQNetwork):
    """Transformer-based DRQN: per-neuron LSTM → attention across neurons; any n.

    per neuron: [v_norm, stimulated, the features of ``sizes.inputs``] → LSTM (H) →
    transformer encoder over the n neuron tokens at each step (attn_layers ×
    attn_heads, width W, FF attn_ff) ⊕ per-neuron context (C) → PerNeuronQHead
    (tdrqn_head_hidden). ``inputs=()`` is the paper-literal variant, where the target
    reaches the network only after the transformer. State (h, c), each [B, n, H].
    """

    mix_name = "mixer"

    def build_mix(self) -> nn.Module:
        """TDRQN's mixing block: self-attention across the neurons."""
        s = self.sizes
        return NeuronMixer(s.lstm_hidden, s.attn_width, s.attn_layers, s.attn_heads, s.attn_ff)

    def head_hidden(self) -> tuple[int, ...]:
        """TDRQN's per-neuron Q head widths (``sizes.tdrqn_head_hidden``)."""
        return self.sizes.tdrqn_head_hidden
