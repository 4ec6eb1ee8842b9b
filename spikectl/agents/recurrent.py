"""What the four networks share: the :class:`RecurrentQNetwork` interface and the base
class that implements the parts of it that do not depend on the architecture.

A network says how it ``encode``\\s a sequence into features and how it turns features
into ``q_values``; the base class adds ``forward`` (the two in turn), ``step`` (the very
same ``forward`` on a T = 1 sequence, so acting and training see the same network) and
``initial_state``. Shapes in comments: B batch, T time, n neurons, H LSTM width,
F per-neuron input features.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

import torch
from torch import nn

from spikectl.agents.encoders import PerNeuronLSTM
from spikectl.agents.inputs import input_width, per_neuron_inputs
from spikectl.agents.observation import (
    OBS_KEYS,
    OPTIONAL_KEYS,
    check_observation,
    check_state,
    long_indices,
)
from spikectl.agents.sizes import AgentSizes
from spikectl.neuron.params import NeuronParams

State = tuple[torch.Tensor, ...]
Observation = Mapping[str, torch.Tensor]


@runtime_checkable
class RecurrentQNetwork(Protocol):
    """The interface all four networks share."""

    episode_length: int
    equivariant: bool

    def initial_state(
        self, batch_size: int, n_neurons: int, device: torch.device | str | None = None
    ) -> State:
        """The zero recurrent state for ``batch_size`` episodes of ``n_neurons`` neurons."""
        ...

    def forward(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """Sequence forward: obs with leading [B, T] → (q [B, T, n+1], final state)."""
        ...

    def step(self, obs: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        """Step forward: obs with leading [B] → (q [B, n+1], new state)."""
        ...


def voltage_range(params: NeuronParams | None) -> tuple[float, float]:
    """(V_r, V_th) of the environment's model, which normalise the voltage input to
    (V - V_r) / (V_th - V_r): rest maps to 0, a visible spike to >= 1."""
    params = NeuronParams() if params is None else params
    if not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams or None, got {type(params).__name__}")
    return params.v_rest_mV, params.v_threshold_mV


class RecurrentQNetworkBase(nn.Module):
    """The architecture-independent part of :class:`RecurrentQNetwork`.

    Subclasses set ``equivariant`` and define ``build``, ``state_shape``, ``encode`` and
    ``q_values``. The base creates no parameters, so the order in which a subclass's
    ``build`` registers its modules alone decides the initial weights a seed gives.
    """

    equivariant: bool

    def __init__(
        self,
        n_neurons: int,
        episode_length: int,
        sizes: AgentSizes | None = None,
        params: NeuronParams | None = None,
    ) -> None:
        super().__init__()
        name = type(self).__name__
        for label, value in (("n_neurons", n_neurons), ("episode_length", episode_length)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: {label} must be an int >= 1, got {value!r}")
        self.sizes = sizes or AgentSizes()
        self.v_rest_mV, self.v_threshold_mV = voltage_range(params)
        self.n_neurons = n_neurons  # an equivariant network runs on any n, not only this one
        self.episode_length = episode_length
        self.build()

    def build(self) -> None:
        """Register the modules, in the order that gives a seed the initial weights it
        always gave (the state-dict keys follow from their names)."""
        raise NotImplementedError

    @property
    def fixed_n(self) -> int | None:
        """The one n the network runs on, or None when it runs on any n."""
        return None if self.equivariant else self.n_neurons

    def param_dtype(self) -> torch.dtype:
        return next(self.parameters()).dtype

    def state_shape(self, batch_size: int, n_neurons: int) -> tuple[int, ...]:
        """The shape of each of the state tensors (h, c)."""
        raise NotImplementedError

    def initial_state(
        self, batch_size: int, n_neurons: int, device: torch.device | str | None = None
    ) -> State:
        """The zero recurrent state for ``batch_size`` episodes of ``n_neurons`` neurons
        (refused for a network built for another fixed n).
        """
        if self.fixed_n is not None and n_neurons != self.fixed_n:
            raise ValueError(
                f"{type(self).__name__}.initial_state: this network is built for a fixed "
                f"number of neurons: expected n = {self.fixed_n}, got n = {n_neurons}"
            )
        shape = self.state_shape(batch_size, n_neurons)
        zeros = torch.zeros(shape, device=device, dtype=self.param_dtype())  # [B, (n,) H]
        return zeros, zeros.clone()

    def forward(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        features, state = self.encode(obs_seq, state)
        return self.q_values(features, obs_seq), state

    def step(self, obs: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        check_observation(
            obs, leading_dims=1, episode_length=self.episode_length, n_neurons=self.fixed_n,
            where=f"{type(self).__name__}.step",
        )  # fmt: skip
        keys = OBS_KEYS + tuple(key for key in OPTIONAL_KEYS if key in obs)
        seq = {key: obs[key].unsqueeze(1) for key in keys}  # [B, 1, ...]
        q, state = self(seq, state)  # q: [B, 1, n+1]
        return q.squeeze(1), state  # [B, n+1]

    def checked_inputs(
        self, obs_seq: Observation, state: State | None
    ) -> tuple[dict[str, torch.Tensor], State]:
        """Check a sequence batch and its state → (the batch with int64 indices, the
        state, zeros when it was None): what ``encode`` starts from."""
        where = f"{type(self).__name__}.forward"
        (B, T), n = check_observation(
            obs_seq, leading_dims=2, episode_length=self.episode_length,
            n_neurons=self.fixed_n, where=where,
        )  # fmt: skip
        obs_seq = long_indices(obs_seq)
        if state is None:
            state = self.initial_state(B, n, device=obs_seq["voltage"].device)
        check_state(state, [self.state_shape(B, n)] * 2, where)
        return obs_seq, state


class PerNeuronMemory(RecurrentQNetworkBase):
    """A network whose memory is the shared per-neuron LSTM (DDRQN, DMDRQN, TDRQN):
    each neuron's features → one LSTM with a state per neuron, (h, c) each [B, n, H]."""

    def build_lstm(self) -> PerNeuronLSTM:
        """The LSTM, for ``build`` to register as ``lstm``, first."""
        s = self.sizes
        return PerNeuronLSTM(input_width(s.inputs), s.lstm_hidden)

    def state_shape(self, batch_size: int, n_neurons: int) -> tuple[int, ...]:
        return batch_size, n_neurons, self.sizes.lstm_hidden

    def lstm_outputs(self, obs_seq: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        """Featurise each neuron and run the per-neuron LSTM → outputs [B, T, n, H] and
        the final state."""
        obs_seq, state = self.checked_inputs(obs_seq, state)
        s = self.sizes
        x = per_neuron_inputs(
            obs_seq, s.inputs, v_rest_mV=self.v_rest_mV, v_threshold_mV=self.v_threshold_mV,
            dtype=self.param_dtype(),
        )  # fmt: skip
        return self.lstm(x, state)  # [B, T, n, H], (h, c)
