"""The paper's four recurrent Q-networks (Section 5.2, App. C and D; docs/agents.md).

- :class:`DRQN`   one LSTM over the whole system, + context → FF → n+1 Q-values.
- :class:`DDRQN`  one shared LSTM with a state per neuron → per-neuron FF, + context
  → per-neuron Q-values; permutation equivariant, any n.
- :class:`DMDRQN` per-neuron LSTM states concatenated across neurons → FF, + context
  → n+1 Q-values; fixed n, not equivariant.
- :class:`TDRQN`  per-neuron LSTM states → transformer across neurons, + context →
  per-neuron Q-values; permutation equivariant, any n.

All four share one interface (:class:`RecurrentQNetwork`): ``initial_state``,
``forward`` over whole sequences ``[B, T]`` and ``step`` over one step ``[B]``;
``step`` runs the very same code as ``forward`` with T = 1, so acting and
training see the same network. Q-vectors are ordered by action + 1 (index 0 = do
nothing). Shapes in comments: B batch, T time, n neurons, H LSTM width,
W attention width, C context width, U per-neuron head input width.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from typing import Literal, Protocol, get_args, runtime_checkable

import torch
from torch import nn

from spikectl.agents.blocks import (
    MLP,
    OBS_KEYS,
    ContextEncoder,
    NeuronMixer,
    NextVoltagePredictor,
    PerNeuronLSTM,
    PerNeuronQHead,
    check_observation,
    check_state,
    long_indices,
    per_neuron_features,
    system_features,
)
from spikectl.neuron.params import NeuronParams

Architecture = Literal["drqn", "ddrqn", "dmdrqn", "tdrqn"]
"""The architectures' names (the paper's order); :data:`AGENTS` maps them to classes."""
ARCHITECTURES: tuple[str, ...] = get_args(Architecture)

State = tuple[torch.Tensor, ...]
Observation = Mapping[str, torch.Tensor]


@dataclass(frozen=True)
class AgentSizes:
    """Sizes and settings of the networks; defaults are the paper's Table 2 (docs/agents.md).

    The fields marked "not in the paper" are this project's choices (docs/agents.md).
    """

    lstm_hidden: int = 128
    """Memory hidden size: LSTM width (per neuron, or of the one system LSTM in DRQN)."""
    target_embed: int = 16
    """Width of the target-neuron code (FF + ReLU); half of the context size 32."""
    pattern_embed: int = 16
    """Width of the shifted-pattern code (FF + ReLU); half of the context size 32."""
    ff_hidden: int = 512
    """Non-transformer FF width: the transformer's stand-in in DDRQN (per neuron) and DMDRQN."""
    head_hidden: tuple[int, ...] = (512, 256, 128)
    """Final FF head widths of DRQN, DDRQN and DMDRQN."""
    tdrqn_head_hidden: tuple[int, ...] = (256, 128)
    """Final FF head widths of TDRQN (Table 2: the 512 layer is not in TDRQN)."""
    attn_width: int = 128
    """Attention hidden size (model width) of TDRQN's transformer encoder."""
    attn_layers: int = 2
    """Number of transformer encoder layers in TDRQN."""
    attn_heads: int = 1
    """Attention heads per layer in TDRQN (must divide attn_width)."""
    attn_ff: int = 256
    """Feed-forward width inside each transformer encoder layer."""
    value_hidden: tuple[int, ...] = (128,)
    """Widths of the pooled do-nothing value MLP of DDRQN and TDRQN (not in the paper)."""
    do_nothing_head: str = "dueling"
    """DDRQN/TDRQN do-nothing Q: 'dueling' (Q_i = V + A_i) or 'pooled' (Q_i = A_i); not in paper."""
    target_in_input: bool = True
    """Target indicator also in each neuron's LSTM input; False = paper-literal (only after)."""
    target_voltage_in_input: bool = False
    """The target's normalised voltage also in each neuron's LSTM input (not in the paper)."""

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if field.type == "int":
                if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                    raise ValueError(f"AgentSizes.{field.name} must be an int >= 1, got {value!r}")
            elif field.type == "tuple[int, ...]":
                if isinstance(value, int) or not all(
                    isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value
                ):
                    raise ValueError(
                        f"AgentSizes.{field.name} must be a sequence of ints >= 1, got {value!r}"
                    )
                object.__setattr__(self, field.name, tuple(value))
        if self.attn_width % self.attn_heads:
            raise ValueError(
                f"AgentSizes.attn_heads ({self.attn_heads}) must divide "
                f"AgentSizes.attn_width ({self.attn_width})"
            )
        if self.do_nothing_head not in PerNeuronQHead.MODES:
            raise ValueError(
                f"AgentSizes.do_nothing_head must be one of {PerNeuronQHead.MODES}, got "
                f"{self.do_nothing_head!r}"
            )
        for name in ("target_in_input", "target_voltage_in_input"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"AgentSizes.{name} must be a bool, got {getattr(self, name)!r}")


def voltage_range(params: NeuronParams | None) -> tuple[float, float]:
    """(V_r, V_th) of the environment's model, which normalise the voltage input to
    (V - V_r) / (V_th - V_r): rest maps to 0, a visible spike to >= 1."""
    params = NeuronParams() if params is None else params
    if not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams or None, got {type(params).__name__}")
    return params.v_rest_mV, params.v_threshold_mV


@runtime_checkable
class RecurrentQNetwork(Protocol):
    """The interface all four networks share."""

    episode_length: int
    equivariant: bool

    def initial_state(
        self, batch_size: int, n_neurons: int, device: torch.device | str | None = None
    ) -> State: ...

    def forward(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """Sequence forward: obs with leading [B, T] → (q [B, T, n+1], final state)."""
        ...

    def step(self, obs: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        """Step forward: obs with leading [B] → (q [B, n+1], new state)."""
        ...


# ----------------------------------------------------------------------------
# small shared helpers (functions, not a base class)


def _check_dims(n_neurons: int, episode_length: int, name: str) -> None:
    for label, value in (("n_neurons", n_neurons), ("episode_length", episode_length)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: {label} must be an int >= 1, got {value!r}")


def per_neuron_width(sizes: AgentSizes) -> int:
    """Features per neuron of the per-neuron LSTM input (see ``per_neuron_features``)."""
    return 2 + sizes.target_in_input + sizes.target_voltage_in_input


def _param_dtype(module: nn.Module) -> torch.dtype:
    return next(module.parameters()).dtype


def _check_fixed_n(expected: int, got: int, where: str) -> None:
    if got != expected:
        raise ValueError(
            f"{where}: this network is built for a fixed number of neurons: expected "
            f"n = {expected}, got n = {got}"
        )


def _step_via_forward(
    net: nn.Module, obs: Observation, state: State | None, n_fixed: int | None
) -> tuple[torch.Tensor, State]:
    """Run ``net.forward`` on a T = 1 sequence: acting uses the training code path."""
    where = f"{type(net).__name__}.step"
    check_observation(
        obs, leading_dims=1, episode_length=net.episode_length, n_neurons=n_fixed, where=where
    )
    seq = {key: obs[key].unsqueeze(1) for key in OBS_KEYS}  # [B, 1, ...]
    q, state = net(seq, state)  # q: [B, 1, n+1]
    return q.squeeze(1), state  # [B, n+1]


def _per_neuron_lstm(
    net: nn.Module, obs_seq: Observation, state: State | None, n_fixed: int | None
) -> tuple[torch.Tensor, State]:
    """The part DDRQN, DMDRQN and TDRQN share: check the observation, featurise each
    neuron and run the shared per-neuron LSTM → outputs [B, T, n, H], final state."""
    where = f"{type(net).__name__}.forward"
    (B, T), n = check_observation(
        obs_seq, leading_dims=2, episode_length=net.episode_length, n_neurons=n_fixed,
        where=where,
    )  # fmt: skip
    obs_seq = long_indices(obs_seq)
    if state is None:
        state = net.initial_state(B, n, device=obs_seq["voltage"].device)
    H = net.lstm.hidden
    check_state(state, [(B, n, H), (B, n, H)], where)
    s = net.sizes
    x = per_neuron_features(
        obs_seq,
        v_rest_mV=net.v_rest_mV,
        v_threshold_mV=net.v_threshold_mV,
        with_target=s.target_in_input,
        with_target_voltage=s.target_voltage_in_input,
        dtype=_param_dtype(net),
    )  # [B, T, n, F]
    return net.lstm(x, state)  # [B, T, n, H], (h, c)


# ----------------------------------------------------------------------------
# the four networks


class DRQN(nn.Module):
    """Baseline: one LSTM over the whole system (fixed n).

    input [v_norm (n), one-hot previous action (n+1)] → LSTM (H) ⊕ context (C,
    one-hot target) → MLP head_hidden → n+1 Q-values. State (h, c), each [B, H].
    """

    equivariant = False

    def __init__(
        self,
        n_neurons: int,
        episode_length: int,
        sizes: AgentSizes | None = None,
        params: NeuronParams | None = None,
    ):
        super().__init__()
        _check_dims(n_neurons, episode_length, "DRQN")
        self.sizes = sizes = sizes or AgentSizes()
        self.v_rest_mV, self.v_threshold_mV = voltage_range(params)
        self.n_neurons = n_neurons
        self.episode_length = episode_length
        self.lstm = nn.LSTM(2 * n_neurons + 1, sizes.lstm_hidden, batch_first=True)
        self.context = ContextEncoder(
            episode_length, sizes.target_embed, sizes.pattern_embed, n_neurons
        )
        self.head = MLP(
            sizes.lstm_hidden + self.context.out_features, sizes.head_hidden, n_neurons + 1
        )
        self.feature_width = sizes.lstm_hidden
        """Width of :meth:`encode`'s output."""

    def initial_state(
        self, batch_size: int, n_neurons: int, device: torch.device | str | None = None
    ) -> State:
        _check_fixed_n(self.n_neurons, n_neurons, "DRQN.initial_state")
        h = torch.zeros(batch_size, self.sizes.lstm_hidden, device=device, dtype=_param_dtype(self))
        return h, h.clone()  # [B, H] each

    def forward(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        features, state = self.encode(obs_seq, state)
        return self.q_values(features, obs_seq), state

    def encode(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """The LSTM's outputs [B, T, H] (what the head and the auxiliary predictor read)."""
        (B, T), n = check_observation(
            obs_seq,
            leading_dims=2,
            episode_length=self.episode_length,
            n_neurons=self.n_neurons,
            where="DRQN.forward",
        )
        obs_seq = long_indices(obs_seq)
        H = self.sizes.lstm_hidden
        if state is None:
            state = self.initial_state(B, n, device=obs_seq["voltage"].device)
        check_state(state, [(B, H), (B, H)], "DRQN.forward")
        x = system_features(
            obs_seq,
            v_rest_mV=self.v_rest_mV,
            v_threshold_mV=self.v_threshold_mV,
            dtype=_param_dtype(self),
        )  # [B, T, 2n+1]
        h0 = state[0].unsqueeze(0).contiguous()  # [1, B, H]
        c0 = state[1].unsqueeze(0).contiguous()  # [1, B, H]
        y, (h, c) = self.lstm(x, (h0, c0))  # y: [B, T, H]
        return y, (h.squeeze(0), c.squeeze(0))  # [B, H] each

    def q_values(self, features: torch.Tensor, obs_seq: Observation) -> torch.Tensor:
        """Features [B, T, H] from :meth:`encode` → Q-values [B, T, n+1]."""
        obs_seq = long_indices(obs_seq)
        n = obs_seq["voltage"].shape[-1]
        z = torch.cat([features, self.context(obs_seq, n)], dim=-1)  # [B, T, H+C]
        return self.head(z)  # [B, T, n+1]

    def step(self, obs: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        return _step_via_forward(self, obs, state, self.n_neurons)


class PerNeuronQNetwork(nn.Module):
    """Per-neuron LSTM → mixing block → per-neuron Q-values; any n, equivariant.

    per neuron: [v_norm, stimulated, (is target), (target voltage)] → LSTM (H) → ``mix``
    ([B, T, n, H] → [B, T, n, M]) ⊕ per-neuron context (C) → PerNeuronQHead
    (``head_hidden``). The mixing block is the only difference between DDRQN (a
    per-neuron FF layer: no mixing) and TDRQN (a transformer across neurons); it is
    registered under ``mix_name`` (``ff``, ``mixer``) so that saved weights keep their
    key names. State (h, c), each [B, n, H].
    """

    equivariant = True

    def __init__(
        self,
        n_neurons: int,
        episode_length: int,
        sizes: AgentSizes | None,
        params: NeuronParams | None = None,
        *,
        mix_name: str,
        make_mix: Callable[[AgentSizes], nn.Module],
        head_hidden: tuple[int, ...],
    ):
        super().__init__()
        _check_dims(n_neurons, episode_length, type(self).__name__)
        self.sizes = sizes = sizes or AgentSizes()
        self.v_rest_mV, self.v_threshold_mV = voltage_range(params)
        self.n_neurons = n_neurons  # the n it was built for; it runs on any n
        self.episode_length = episode_length
        # Built in this order (LSTM, mix, context, head) so that a seed gives the
        # initial weights it always gave.
        self.lstm = PerNeuronLSTM(per_neuron_width(sizes), sizes.lstm_hidden)
        self.mix_name = mix_name
        self.add_module(mix_name, make_mix(sizes))
        self.context = ContextEncoder(episode_length, sizes.target_embed, sizes.pattern_embed, None)
        self.head = PerNeuronQHead(
            self.mix.out_features + self.context.out_features,
            head_hidden,
            sizes.value_hidden,
            sizes.do_nothing_head,
        )
        self.feature_width = self.mix.out_features
        """Width of :meth:`encode`'s per-neuron output."""

    @property
    def mix(self) -> nn.Module:
        """The mixing block, [B, T, n, H] → [B, T, n, M]."""
        return self.get_submodule(self.mix_name)

    def initial_state(
        self, batch_size: int, n_neurons: int, device: torch.device | str | None = None
    ) -> State:
        return self.lstm.initial_state(batch_size, n_neurons, device, _param_dtype(self))

    def forward(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        features, state = self.encode(obs_seq, state)
        return self.q_values(features, obs_seq), state

    def encode(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """Per-neuron embeddings [B, T, n, M] before the context and the head."""
        y, state = _per_neuron_lstm(self, obs_seq, state, n_fixed=None)  # [B, T, n, H]
        return self.mix(y), state  # [B, T, n, M]

    def q_values(self, features: torch.Tensor, obs_seq: Observation) -> torch.Tensor:
        """Features [B, T, n, M] from :meth:`encode` → Q-values [B, T, n+1]."""
        obs_seq = long_indices(obs_seq)
        context = self.context(obs_seq, features.shape[-2])  # [B, T, n, C]
        u = torch.cat([features, context], dim=-1)  # [B, T, n, M+C]
        return self.head(u, obs_seq["target"])  # [B, T, n+1]

    def step(self, obs: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        return _step_via_forward(self, obs, state, None)


def feed_forward_mix(sizes: AgentSizes) -> nn.Module:
    """DDRQN's block: one FF layer (ff_hidden + ReLU) per neuron, no mixing."""
    return MLP(sizes.lstm_hidden, [sizes.ff_hidden], None)


def attention_mix(sizes: AgentSizes) -> nn.Module:
    """TDRQN's block: a transformer encoder over the n neuron tokens at each step."""
    return NeuronMixer(
        sizes.lstm_hidden, sizes.attn_width, sizes.attn_layers, sizes.attn_heads, sizes.attn_ff
    )


class DDRQN(PerNeuronQNetwork):
    """Distributed DRQN: shared per-neuron LSTM → per-neuron FF; any n, equivariant.

    per neuron: [v_norm, stimulated, (is target)] → LSTM (H) → FF ff_hidden + ReLU
    ⊕ per-neuron context (C) → PerNeuronQHead (head_hidden). No mixing between
    neurons except the pooled do-nothing value. State (h, c), each [B, n, H].
    """

    def __init__(
        self,
        n_neurons: int,
        episode_length: int,
        sizes: AgentSizes | None = None,
        params: NeuronParams | None = None,
    ):
        sizes = sizes or AgentSizes()
        super().__init__(
            n_neurons,
            episode_length,
            sizes,
            params,
            mix_name="ff",
            make_mix=feed_forward_mix,
            head_hidden=sizes.head_hidden,
        )


class DMDRQN(nn.Module):
    """Distribute-and-Mix DRQN: per-neuron LSTM states concatenated (fixed n).

    per neuron: [v_norm, stimulated, (is target)] → LSTM (H); concat over neurons
    (n*H) → FF ff_hidden + ReLU ⊕ context (C, one-hot target) → MLP head_hidden →
    n+1 Q-values. State (h, c), each [B, n, H].
    """

    equivariant = False

    def __init__(
        self,
        n_neurons: int,
        episode_length: int,
        sizes: AgentSizes | None = None,
        params: NeuronParams | None = None,
    ):
        super().__init__()
        _check_dims(n_neurons, episode_length, "DMDRQN")
        self.sizes = sizes = sizes or AgentSizes()
        self.v_rest_mV, self.v_threshold_mV = voltage_range(params)
        self.n_neurons = n_neurons
        self.episode_length = episode_length
        self.lstm = PerNeuronLSTM(per_neuron_width(sizes), sizes.lstm_hidden)
        self.mix = MLP(n_neurons * sizes.lstm_hidden, [sizes.ff_hidden], None)
        self.context = ContextEncoder(
            episode_length, sizes.target_embed, sizes.pattern_embed, n_neurons
        )
        self.head = MLP(
            self.mix.out_features + self.context.out_features, sizes.head_hidden, n_neurons + 1
        )
        self.feature_width = self.mix.out_features
        """Width of :meth:`encode`'s output."""

    def initial_state(
        self, batch_size: int, n_neurons: int, device: torch.device | str | None = None
    ) -> State:
        _check_fixed_n(self.n_neurons, n_neurons, "DMDRQN.initial_state")
        return self.lstm.initial_state(batch_size, n_neurons, device, _param_dtype(self))

    def forward(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        features, state = self.encode(obs_seq, state)
        return self.q_values(features, obs_seq), state

    def encode(
        self, obs_seq: Observation, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """The mixed system embedding [B, T, ff_hidden] before the context and the head."""
        y, state = _per_neuron_lstm(self, obs_seq, state, n_fixed=self.n_neurons)
        B, T, n, H = y.shape
        y = y.reshape(B, T, n * H)  # [B, T, n*H]
        return self.mix(y), state  # [B, T, ff_hidden]

    def q_values(self, features: torch.Tensor, obs_seq: Observation) -> torch.Tensor:
        """Features [B, T, ff_hidden] from :meth:`encode` → Q-values [B, T, n+1]."""
        obs_seq = long_indices(obs_seq)
        n = obs_seq["voltage"].shape[-1]
        z = torch.cat([features, self.context(obs_seq, n)], dim=-1)  # [B, T, ff_hidden+C]
        return self.head(z)  # [B, T, n+1]

    def step(self, obs: Observation, state: State | None) -> tuple[torch.Tensor, State]:
        return _step_via_forward(self, obs, state, self.n_neurons)


class TDRQN(PerNeuronQNetwork):
    """Transformer-based DRQN: per-neuron LSTM → attention across neurons; any n.

    per neuron: [v_norm, stimulated, (is target)] → LSTM (H) → transformer encoder
    over the n neuron tokens at each step (attn_layers × attn_heads, width W, FF
    attn_ff) ⊕ per-neuron context (C) → PerNeuronQHead (tdrqn_head_hidden).
    ``target_in_input=False`` is the paper-literal variant, where the target
    reaches the network only after the transformer. State (h, c), each [B, n, H].
    """

    def __init__(
        self,
        n_neurons: int,
        episode_length: int,
        sizes: AgentSizes | None = None,
        params: NeuronParams | None = None,
    ):
        sizes = sizes or AgentSizes()
        super().__init__(
            n_neurons,
            episode_length,
            sizes,
            params,
            mix_name="mixer",
            make_mix=attention_mix,
            head_hidden=sizes.tdrqn_head_hidden,
        )


# ----------------------------------------------------------------------------
# construction


AGENTS: dict[str, type[nn.Module]] = dict(
    zip(ARCHITECTURES, (DRQN, DDRQN, DMDRQN, TDRQN), strict=True)
)
"""Architecture name → class."""


def make_agent(
    name: str,
    n_neurons: int,
    episode_length: int,
    sizes: AgentSizes | None = None,
    params: NeuronParams | None = None,
    **overrides: object,
) -> nn.Module:
    """Build one of the four networks by name (drqn, ddrqn, dmdrqn, tdrqn).

    ``sizes`` defaults to Table 2 (:class:`AgentSizes`); keyword overrides replace
    single fields, e.g. ``make_agent("tdrqn", 8, 60, lstm_hidden=64)``. ``params`` are
    the environment's model parameters (default: Table 1): their V_r and V_th normalise
    the voltage input.
    """
    key = name.lower() if isinstance(name, str) else name
    if key not in AGENTS:
        raise ValueError(f"unknown agent {name!r}; choose one of {sorted(AGENTS)}")
    valid = {f.name for f in fields(AgentSizes)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        raise TypeError(f"make_agent: unknown size fields {unknown}; valid fields: {sorted(valid)}")
    sizes = replace(sizes or AgentSizes(), **overrides)
    return AGENTS[key](n_neurons, episode_length, sizes, params)


def make_voltage_predictor(network: nn.Module) -> NextVoltagePredictor:
    """The auxiliary next-voltage head that reads ``network.encode``'s features."""
    n_fixed = None if network.equivariant else network.n_neurons
    return NextVoltagePredictor(network.feature_width, n_fixed)


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


def parameter_counts(
    n_neurons: int = 8, episode_length: int = 60, sizes: AgentSizes | None = None
) -> dict[str, int]:
    """Trainable parameters of each architecture (default: Table 2 sizes, n = 8, N = 60)."""
    return {
        name: count_parameters(make_agent(name, n_neurons, episode_length, sizes))
        for name in AGENTS
    }


def reset_state(state: State, done: torch.Tensor) -> State:
    """Zero the hidden state of the batch rows where ``done`` [B] (bool) is True.

    Every state tensor has the batch first, so this serves all four networks
    (e.g. when some of several parallel episodes restart).
    """
    return tuple(
        s.masked_fill(done.reshape(-1, *([1] * (s.dim() - 1))), 0.0)  # [B, ...]
        for s in state
    )
