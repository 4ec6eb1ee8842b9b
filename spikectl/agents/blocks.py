"""Building blocks shared by the four recurrent Q-networks (docs/agents.md, paper App. C).

Shapes in comments use B = batch (episodes), T = time steps, n = neurons,
N = episode length (= pattern length), F = per-neuron input features,
H = LSTM width, W = attention width, C = context width (16 + 16).

The observation contract (one step of the environment, as a dict):

- ``voltage``     float   membrane potentials in mV, one per neuron
- ``target``      int     index of the target neuron
- ``pattern``     0/1     the target spike pattern, length N
- ``step``        int     index t of the step about to be taken (0..N)
- ``last_action`` int     previous action, -1 = did nothing / episode start

Networks take the same keys as torch tensors with a leading ``[B, T]`` (sequence
forward) or ``[B]`` (step forward). Q-value vectors have n + 1 entries ordered by
``action + 1``: index 0 = do nothing, index j + 1 = stimulate neuron j.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

OBS_KEYS = ("voltage", "target", "pattern", "step", "last_action")
"""Keys every observation batch must hold (extra keys are ignored)."""

_INDEX_KEYS = ("target", "step", "last_action")


# ----------------------------------------------------------------------------
# observation checks and conversion


def check_observation(
    obs: Mapping[str, torch.Tensor],
    *,
    leading_dims: int,
    episode_length: int,
    n_neurons: int | None,
    where: str,
) -> tuple[tuple[int, ...], int]:
    """Validate an observation batch; return (leading shape, n).

    ``leading_dims`` is 2 for a sequence batch ``[B, T, ...]`` and 1 for a step
    batch ``[B, ...]``. ``n_neurons`` is the fixed n of the network, or None when
    the network accepts any n. Only cheap checks: keys, types, dtypes and shapes
    always; value ranges only for tensors on the CPU, where they cost no device
    synchronisation.
    """
    voltage_shape = "[B, T, n]" if leading_dims == 2 else "[B, n]"
    if not isinstance(obs, Mapping):
        raise TypeError(f"{where}: observation must be a dict of tensors, got {type(obs).__name__}")
    missing = [key for key in OBS_KEYS if key not in obs]
    if missing:
        raise ValueError(
            f"{where}: observation is missing keys {missing}; expected keys {list(OBS_KEYS)}"
        )
    for key in OBS_KEYS:
        if not isinstance(obs[key], torch.Tensor):
            raise TypeError(
                f"{where}: obs[{key!r}] must be a torch.Tensor, got {type(obs[key]).__name__} "
                "(convert with spikectl.agents.observation_batch or torch.as_tensor)"
            )

    voltage = obs["voltage"]
    if not voltage.is_floating_point():
        raise TypeError(f"{where}: obs['voltage'] must be floating point, got {voltage.dtype}")
    if voltage.dim() != leading_dims + 1:
        raise ValueError(
            f"{where}: obs['voltage'] must have shape {voltage_shape}, got {tuple(voltage.shape)}"
        )
    lead = tuple(voltage.shape[:leading_dims])
    n = int(voltage.shape[-1])
    if n < 1:
        raise ValueError(f"{where}: obs['voltage'] has no neurons (shape {tuple(voltage.shape)})")
    if n_neurons is not None and n != n_neurons:
        raise ValueError(
            f"{where}: this network is built for a fixed number of neurons: expected "
            f"n = {n_neurons}, got n = {n} (only the per-neuron networks DDRQN and TDRQN "
            "run on any n)"
        )
    for key in _INDEX_KEYS:
        value = obs[key]
        if value.is_floating_point() or value.is_complex() or value.dtype == torch.bool:
            raise TypeError(f"{where}: obs[{key!r}] must be an integer tensor, got {value.dtype}")
        if tuple(value.shape) != lead:
            raise ValueError(
                f"{where}: obs[{key!r}] must have shape {lead} (the leading dims of "
                f"obs['voltage']), got {tuple(value.shape)}"
            )
    pattern = obs["pattern"]
    if pattern.is_complex():
        raise TypeError(f"{where}: obs['pattern'] must be real (0/1), got {pattern.dtype}")
    if tuple(pattern.shape) != lead + (episode_length,):
        raise ValueError(
            f"{where}: obs['pattern'] must have shape {lead + (episode_length,)} (pattern "
            f"length = episode length {episode_length}), got {tuple(pattern.shape)}"
        )

    # Inside vmap (stacked seed groups) values cannot be read without leaving the
    # transform; shapes and dtypes are still checked, and the trainer's inputs come
    # from the environment and the replay buffer.
    if voltage.device.type == "cpu" and voltage.numel() > 0 and not _is_transformed(voltage):
        _check_range(obs["target"], 0, n - 1, "target", where)
        _check_range(obs["last_action"], -1, n - 1, "last_action", where)
        _check_range(obs["step"], 0, episode_length, "step", where)
    return lead, n


def _is_transformed(tensor: torch.Tensor) -> bool:
    """Whether ``tensor`` is wrapped by a torch.func transform (vmap, grad)."""
    return torch._C._functorch.is_functorch_wrapped_tensor(tensor)


def _check_range(value: torch.Tensor, low: int, high: int, key: str, where: str) -> None:
    lo, hi = int(value.min()), int(value.max())
    if lo < low or hi > high:
        raise ValueError(f"{where}: obs[{key!r}] must lie in [{low}, {high}], got [{lo}, {hi}]")


def check_state(
    state: tuple[torch.Tensor, ...], expected: Sequence[tuple[int, ...]], where: str
) -> None:
    """Check that a hidden state is a tuple of tensors of the expected shapes."""
    if not isinstance(state, tuple) or len(state) != len(expected):
        raise TypeError(
            f"{where}: state must be a tuple of {len(expected)} tensors (from initial_state), "
            f"got {type(state).__name__}"
        )
    for i, (tensor, shape) in enumerate(zip(state, expected, strict=True)):
        if not isinstance(tensor, torch.Tensor) or tuple(tensor.shape) != tuple(shape):
            got = tuple(tensor.shape) if isinstance(tensor, torch.Tensor) else type(tensor).__name__
            raise ValueError(f"{where}: state[{i}] must have shape {tuple(shape)}, got {got}")


def observation_batch(
    observations: Mapping[str, object] | Sequence[Mapping[str, object]],
    device: torch.device | str | None = None,
) -> dict[str, torch.Tensor]:
    """Environment observations (NumPy arrays / ints) → a step batch [B] of tensors.

    Takes either a sequence of single-environment observations (stacked along a
    new batch dimension) or one already batched dict, as a vector environment
    returns it. The result is what ``network.step`` takes: voltage float32 [B, n],
    pattern float32 [B, N], and target / step / last_action int64 [B].
    """
    if isinstance(observations, Mapping):
        missing = [key for key in OBS_KEYS if key not in observations]
        if missing:
            raise ValueError(f"observation_batch: the batch lacks keys {missing}")
        arrays = {key: np.asarray(observations[key]) for key in OBS_KEYS}
    else:
        if len(observations) == 0:
            raise ValueError("observation_batch: need at least one observation")
        try:
            arrays = {key: np.stack([np.asarray(o[key]) for o in observations]) for key in OBS_KEYS}
        except KeyError as error:
            raise ValueError(f"observation_batch: an observation lacks key {error}") from None
    out: dict[str, torch.Tensor] = {}
    for key, array in arrays.items():
        dtype = np.int64 if key in _INDEX_KEYS else np.float32
        out[key] = torch.as_tensor(array.astype(dtype, copy=False), device=device)
    return out


def long_indices(obs: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The observation with target / step / last_action as int64 (no copy if they are)."""
    out = {key: obs[key] for key in OBS_KEYS}
    for key in _INDEX_KEYS:
        out[key] = out[key].long()
    return out


# ----------------------------------------------------------------------------
# featurisation (pure functions of the observation tensors)


def normalised_voltage(
    voltage: torch.Tensor, v_rest_mV: float, v_threshold_mV: float
) -> torch.Tensor:
    """(V - V_r) / (V_th - V_r): 0 at rest, 1 at threshold (a visible spike is >= 1)."""
    return (voltage - v_rest_mV) / (v_threshold_mV - v_rest_mV)


def neuron_indicator(index: torch.Tensor, n: int, dtype: torch.dtype) -> torch.Tensor:
    """[...] integer → [..., n] with 1 where the neuron is ``index`` (-1 gives all zeros)."""
    neurons = torch.arange(n, device=index.device)  # [n]
    return (index.unsqueeze(-1) == neurons).to(dtype)  # [..., n]


def action_one_hot(last_action: torch.Tensor, n: int, dtype: torch.dtype) -> torch.Tensor:
    """[...] action in -1..n-1 → [..., n+1] one-hot in Q-vector order (index = action + 1)."""
    return F.one_hot(last_action + 1, n + 1).to(dtype)  # [..., n+1]


def shift_pattern(pattern: torch.Tensor, step: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Shift the pattern so step t comes first, pad with -1 to length N (paper App. C).

    pattern [..., N] (0/1), step [...] in 0..N → [..., N] equal to
    ``pattern[t:N]`` followed by ``t`` entries of -1 (all -1 at t = N).
    """
    N = pattern.shape[-1]
    index = step.unsqueeze(-1) + torch.arange(N, device=step.device)  # [..., N]
    shifted = torch.gather(pattern.to(dtype), -1, index.clamp(max=N - 1))  # [..., N]
    return torch.where(index < N, shifted, torch.full_like(shifted, -1.0))  # [..., N]


def per_neuron_features(
    obs: Mapping[str, torch.Tensor],
    *,
    v_rest_mV: float,
    v_threshold_mV: float,
    with_target: bool,
    dtype: torch.dtype,
    with_target_voltage: bool = False,
) -> torch.Tensor:
    """Per-neuron LSTM input [..., n, F]: normalised V, stimulated at t-1, (is target),
    (the target's normalised V).

    F = 2 + with_target + with_target_voltage (docs/agents.md). The target's voltage, the same
    for every neuron, keeps the input permutation equivariant and lets each neuron's
    memory relate its own spikes to the target's response.
    """
    voltage = normalised_voltage(obs["voltage"].to(dtype), v_rest_mV, v_threshold_mV)  # [..., n]
    n = voltage.shape[-1]
    columns = [voltage, neuron_indicator(obs["last_action"], n, dtype)]  # [..., n] each
    if with_target:
        columns.append(neuron_indicator(obs["target"], n, dtype))  # [..., n]
    if with_target_voltage:
        target_voltage = torch.gather(voltage, -1, obs["target"].unsqueeze(-1))  # [..., 1]
        columns.append(target_voltage.expand_as(voltage))  # [..., n]
    return torch.stack(columns, dim=-1)  # [..., n, F]


def system_features(
    obs: Mapping[str, torch.Tensor], *, v_rest_mV: float, v_threshold_mV: float, dtype: torch.dtype
) -> torch.Tensor:
    """DRQN input [..., 2n+1]: all normalised potentials and the one-hot previous action."""
    voltage = obs["voltage"].to(dtype)  # [..., n]
    n = voltage.shape[-1]
    return torch.cat(
        [
            normalised_voltage(voltage, v_rest_mV, v_threshold_mV),  # [..., n]
            action_one_hot(obs["last_action"], n, dtype),  # [..., n+1]
        ],
        dim=-1,
    )  # [..., 2n+1]


# ----------------------------------------------------------------------------
# modules


class MLP(nn.Sequential):
    """Linear + ReLU for each hidden width, then a plain Linear to ``out_features``.

    With ``out_features=None`` it ends with the last hidden ReLU.
    """

    def __init__(self, in_features: int, hidden: Sequence[int], out_features: int | None) -> None:
        layers: list[nn.Module] = []
        width = in_features
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
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

    def initial_state(
        self, batch_size: int, n: int, device: torch.device | str | None, dtype: torch.dtype
    ) -> tuple[torch.Tensor, torch.Tensor]:
        zeros = torch.zeros(batch_size, n, self.hidden, device=device, dtype=dtype)  # [B, n, H]
        return zeros, zeros.clone()

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
        self, in_features: int, hidden: Sequence[int], value_hidden: Sequence[int], mode: str
    ) -> None:
        super().__init__()
        if mode not in self.MODES:
            raise ValueError(f"do-nothing head mode must be one of {self.MODES}, got {mode!r}")
        self.mode = mode
        self.advantage = MLP(in_features, hidden, 1)
        self.value = MLP(2 * in_features, value_hidden, 1)

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


# ----------------------------------------------------------------------------
# acting helpers


def masked_q(
    q: torch.Tensor, action_mask: torch.Tensor, fill: float = float("-inf")
) -> torch.Tensor:
    """Set the Q-values of illegal actions to ``fill`` (default -inf).

    q [..., n+1] and action_mask bool [..., n+1] (True = legal) in action+1 order;
    the mask broadcasts against q (e.g. a [B, n+1] mask over q [B, T, n+1] needs
    ``mask[:, None]``). Use before argmax for acting and for double-Q targets.
    """
    if action_mask.dtype != torch.bool:
        raise TypeError(
            f"masked_q: action_mask must be bool (True = legal), got {action_mask.dtype}"
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
