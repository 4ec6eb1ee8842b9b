"""The networks that read the whole system at once and so run on a fixed n: DRQN and
DMDRQN (paper Section 5.2, App. C and D).

Both end the same way: their system embedding ⊕ the context (one-hot target, shifted
pattern) → MLP ``head_hidden`` → n+1 Q-values. They differ in the memory: DRQN has one
LSTM over all neurons, DMDRQN the shared per-neuron LSTM whose states are concatenated
across neurons. Shapes in comments: B batch, T time, n neurons, H LSTM width, C context
width, D system embedding width.
"""

from __future__ import annotations

import torch
from torch import nn

from spikectl.agents.encoders import MLP, ContextEncoder
from spikectl.agents.features import system_features
from spikectl.agents.observation import long_indices
from spikectl.agents.recurrent import (
    Observation,
    PerNeuronMemory,
    RecurrentQNetworkBase,
    State,
)


class SystemQNetwork(RecurrentQNetworkBase):
    """DRQN's and DMDRQN's common end: the context encoder and the Q head over a system
    embedding [B, T, D]."""

    equivariant = False

    def build_context_and_head(self, feature_width: int) -> None:
        """Register ``context`` and ``head`` for features [B, T, feature_width]; called
        after the memory is built, the order that gives a seed its initial weights."""
        s, n = self.sizes, self.n_neurons
        self.context = ContextEncoder(self.episode_length, s.target_embed, s.pattern_embed, n)
        self.head = MLP(
            feature_width + self.context.out_features, s.head_hidden, n + 1, s.layer_norm
        )
        self.feature_width = feature_width
        """Width of :meth:`encode`'s output."""

    def q_values(self, features: torch.Tensor, obs_seq: Observation) -> torch.Tensor:
        """Features [B, T, D] from :meth:`encode` → Q-values [B, T, n+1]."""
        obs_seq = long_indices(obs_seq)
        n = obs_seq["voltage"].shape[-1]
        z = torch.cat([features, self.context(obs_seq, n)], dim=-1)  # [B, T, D+C]
        return self.head(z)  # [B, T, n+1]


class DRQN(SystemQNetwork):
    """Baseline: one LSTM over the whole system (fixed n).

    input [v_norm (n), one-hot previous action (n+1)] → LSTM (H) ⊕ context (C,
    one-hot target) → MLP head_hidden → n+1 Q-values. State (h, c), each [B, H].
    """

    def build(self) -> None:
        """One LSTM over the whole network's input vector, then the context and the head."""
        n, H = self.n_neurons, self.sizes.lstm_hidden
        self.lstm = nn.LSTM(2 * n + 1, H, batch_first=True)
        self.build_context_and_head(H)

    def state_shape(self, batch_size: int, n_neurons: int) -> tuple[int, ...]:
        """The LSTM state of one of the pair: ``(batch_size, lstm_hidden)``."""
        return batch_size, self.sizes.lstm_hidden

    def encode(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """The LSTM's outputs [B, T, H] (what the head and the auxiliary predictor read)."""
        obs_seq, state = self.checked_inputs(obs_seq, state)
        x = system_features(
            obs_seq,
            v_rest_mV=self.v_rest_mV,
            v_threshold_mV=self.v_threshold_mV,
            dtype=self.param_dtype(),
        )  # [B, T, 2n+1]
        # nn.LSTM wants a leading layer dimension on the state.
        h0 = state[0].unsqueeze(0).contiguous()  # [1, B, H]
        c0 = state[1].unsqueeze(0).contiguous()  # [1, B, H]
        y, (h, c) = self.lstm(x, (h0, c0))  # y: [B, T, H]
        return y, (h.squeeze(0), c.squeeze(0))  # [B, H] each


class DMDRQN(SystemQNetwork, PerNeuronMemory):
    """Distribute-and-Mix DRQN: per-neuron LSTM states concatenated (fixed n).

    per neuron: [v_norm, stimulated, ``sizes.inputs``] → LSTM (H); concat over neurons
    (n*H) → FF ff_hidden + ReLU ⊕ context (C, one-hot target) → MLP head_hidden →
    n+1 Q-values. State (h, c), each [B, n, H].
    """

    def build(self) -> None:
        """The shared per-neuron LSTM, a feed-forward layer over all neurons, the head."""
        self.lstm = self.build_lstm()
        s = self.sizes
        self.mix = MLP(self.n_neurons * s.lstm_hidden, [s.ff_hidden], None, s.layer_norm)
        self.build_context_and_head(self.mix.out_features)

    def encode(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """The mixed system embedding [B, T, ff_hidden] before the context and the head."""
        y, state = self.lstm_outputs(obs_seq, state)  # [B, T, n, H]
        B, T, n, H = y.shape
        y = y.reshape(B, T, n * H)  # [B, T, n*H]
        return self.mix(y), state  # [B, T, ff_hidden]
