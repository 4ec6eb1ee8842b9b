"""A trained per-neuron Q-network as a compiled policy: the per-step recurrent forward in
one Numba function, loaded from a file that needs neither PyTorch nor the trainer
(issue 24; docs/realtime.md).

``export_policy(network, path)`` writes a TDRQN or DDRQN (:func:`make_agent`, trained or
not) to one ``.npz`` file: a JSON header (format name and version, the architecture, the
sizes and options the forward needs) and every weight as a float32 array under its
state-dict name. ``CompiledPolicy.load(path)`` reads it back, checks it, and acts with
the interface the planners have: ``reset()`` and ``act(observation, info) -> int``, the
masked greedy action of one environment, carrying the recurrent state itself.

Importing this module imports NumPy and Numba only; :func:`export_policy` imports
PyTorch inside, since it reads a PyTorch network. The forward is the networks' own
(docs/agents.md): per-neuron features → LSTM cell → transformer encoder across neurons
(TDRQN) or a per-neuron FF layer (DDRQN) → per-neuron context → Q head, with both
do-nothing forms and both target-indicator options; ``test_compiled_policy.py`` checks
that it picks the PyTorch network's actions. Shapes in comments: n neurons, N episode
length, F per-neuron input features, H LSTM width, W attention width, M mixing output
width, E / P target / pattern code widths, U = M + E + P head input width.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numba
import numpy as np

from spikectl.files import atomic_write_bytes, check_regular_file

FORMAT_NAME = "spikectl.CompiledPolicy"
FORMAT_VERSION = 1
SUPPORTED_ARCHITECTURES = ("tdrqn", "ddrqn")
"""What :func:`export_policy` compiles: the per-neuron networks (any n). DRQN and DMDRQN,
fixed-n system networks, are not supported."""
HEADER_KEY = "metadata"


class PolicyFileError(ValueError):
    """A compiled-policy file that is unreadable, foreign, of another version, or whose
    weights do not match its header (the message names the file and the problem)."""


@dataclass(frozen=True)
class PolicySpec:
    """What the compiled forward needs besides the weights: the file's header."""

    architecture: str
    """``tdrqn`` or ``ddrqn``."""
    n_neurons: int
    """The n the network was built for (it runs on any n)."""
    episode_length: int
    """N, the pattern length."""
    v_rest_mV: float
    v_threshold_mV: float
    """The potentials that normalise the voltage input: (V - V_r) / (V_th - V_r)."""
    lstm_hidden: int
    target_embed: int
    pattern_embed: int
    mix_hidden: int
    """DDRQN's per-neuron FF width (``ff_hidden``); unused by TDRQN."""
    attn_width: int
    attn_layers: int
    attn_heads: int
    attn_ff: int
    """TDRQN's transformer; unused by DDRQN."""
    layer_norm_eps: float
    head_hidden: tuple[int, ...]
    """The per-neuron Q head's hidden widths (``tdrqn_head_hidden`` or ``head_hidden``)."""
    value_hidden: tuple[int, ...]
    do_nothing_head: str
    target_in_input: bool
    target_voltage_in_input: bool

    @property
    def input_features(self) -> int:
        """F: [v_norm, stimulated, (is target), (target's v_norm)]."""
        return 2 + self.target_in_input + self.target_voltage_in_input

    @property
    def mix_width(self) -> int:
        """M: the width of each neuron's embedding after the mixing block."""
        return self.attn_width if self.architecture == "tdrqn" else self.mix_hidden

    def weight_shapes(self) -> dict[str, tuple[int, ...]]:
        """Every weight's state-dict name → shape, as the PyTorch network holds them."""
        F, H, W = self.input_features, self.lstm_hidden, self.attn_width
        shapes: dict[str, tuple[int, ...]] = {
            "lstm.lstm.weight_ih_l0": (4 * H, F),
            "lstm.lstm.weight_hh_l0": (4 * H, H),
            "lstm.lstm.bias_ih_l0": (4 * H,),
            "lstm.lstm.bias_hh_l0": (4 * H,),
        }
        if self.architecture == "tdrqn":
            if H != W:
                shapes |= {"mixer.project.weight": (W, H), "mixer.project.bias": (W,)}
            for layer in range(self.attn_layers):
                prefix = f"mixer.encoder.layers.{layer}."
                for name, shape in (
                    ("self_attn.in_proj_weight", (3 * W, W)),
                    ("self_attn.in_proj_bias", (3 * W,)),
                    ("self_attn.out_proj.weight", (W, W)),
                    ("self_attn.out_proj.bias", (W,)),
                    ("linear1.weight", (self.attn_ff, W)),
                    ("linear1.bias", (self.attn_ff,)),
                    ("linear2.weight", (W, self.attn_ff)),
                    ("linear2.bias", (W,)),
                    ("norm1.weight", (W,)),
                    ("norm1.bias", (W,)),
                    ("norm2.weight", (W,)),
                    ("norm2.bias", (W,)),
                ):
                    shapes[prefix + name] = shape
        else:
            shapes |= {"ff.0.weight": (self.mix_hidden, H), "ff.0.bias": (self.mix_hidden,)}
        E, P, N = self.target_embed, self.pattern_embed, self.episode_length
        shapes |= {
            "context.target.0.weight": (E, 1),
            "context.target.0.bias": (E,),
            "context.pattern.0.weight": (P, N),
            "context.pattern.0.bias": (P,),
        }
        U = self.mix_width + E + P
        for name, width, hidden in (("advantage", U, self.head_hidden),
                                    ("value", 2 * U, self.value_hidden)):  # fmt: skip
            for index, out in enumerate((*hidden, 1)):
                # MLP = Linear, ReLU, Linear, ..., Linear: the linears sit at even indices.
                shapes[f"head.{name}.{2 * index}.weight"] = (out, width)
                shapes[f"head.{name}.{2 * index}.bias"] = (out,)
                width = out
        return shapes


def _spec_of(network: Any) -> PolicySpec:
    """The header of a PyTorch TDRQN or DDRQN; refuses what the forward does not cover."""
    from spikectl.agents.per_neuron_networks import DDRQN, TDRQN

    if isinstance(network, TDRQN):
        architecture = "tdrqn"
    elif isinstance(network, DDRQN):
        architecture = "ddrqn"
    else:
        raise ValueError(
            f"export_policy: cannot compile a {type(network).__name__}; supported "
            f"architectures: {', '.join(SUPPORTED_ARCHITECTURES)} (make_agent's TDRQN and DDRQN)"
        )
    s = network.sizes
    eps = 1e-5
    if architecture == "tdrqn":
        encoder = network.mixer.encoder
        layers = list(encoder.layers)
        if encoder.norm is not None or any(
            layer.norm_first or layer.activation_relu_or_gelu != 1 for layer in layers
        ):
            raise ValueError(
                "export_policy: the compiled TDRQN supports post-norm encoder layers with "
                "ReLU and no final norm (what make_agent builds)"
            )
        eps = float(layers[0].norm1.eps)
    return PolicySpec(
        architecture=architecture,
        n_neurons=int(network.n_neurons),
        episode_length=int(network.episode_length),
        v_rest_mV=float(network.v_rest_mV),
        v_threshold_mV=float(network.v_threshold_mV),
        lstm_hidden=s.lstm_hidden,
        target_embed=s.target_embed,
        pattern_embed=s.pattern_embed,
        mix_hidden=s.ff_hidden,
        attn_width=s.attn_width,
        attn_layers=s.attn_layers,
        attn_heads=s.attn_heads,
        attn_ff=s.attn_ff,
        layer_norm_eps=eps,
        head_hidden=tuple(s.tdrqn_head_hidden if architecture == "tdrqn" else s.head_hidden),
        value_hidden=tuple(s.value_hidden),
        do_nothing_head=s.do_nothing_head,
        target_in_input=s.target_in_input,
        target_voltage_in_input=s.target_voltage_in_input,
    )


def _policy_bytes(network: Any) -> bytes:
    """The ``.npz`` file of a network, in memory."""
    spec = _spec_of(network)
    weights = {
        name: tensor.detach().cpu().float().numpy() for name, tensor in network.state_dict().items()
    }
    expected = spec.weight_shapes()
    shapes = {name: tuple(array.shape) for name, array in weights.items()}
    if shapes != expected:  # the exporter and the loader must agree on every weight
        raise ValueError(
            f"export_policy: the {spec.architecture} network's weights "
            f"{_mismatch(expected, shapes)}"
        )
    header = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, **asdict(spec)}
    buffer = io.BytesIO()
    np.savez(buffer, **{HEADER_KEY: np.array(json.dumps(header))}, **weights)
    return buffer.getvalue()


def export_policy(network: Any, path: str | Path) -> Path:
    """Write a TDRQN or DDRQN to ``path`` (``.npz``), atomically, for
    :meth:`CompiledPolicy.load`. Returns the path. Other architectures raise
    ``ValueError`` naming the supported ones."""
    return atomic_write_bytes(path, _policy_bytes(network))


def _mismatch(expected: Mapping[str, tuple], actual: Mapping[str, tuple]) -> str:
    """What differs between two {name: shape} tables, in one line."""
    problems = []
    missing = sorted(set(expected) - set(actual))
    extra = sorted(set(actual) - set(expected))
    if missing:
        problems.append(f"lack {missing}")
    if extra:
        problems.append(f"have unexpected {extra}")
    for name in sorted(set(expected) & set(actual)):
        if tuple(expected[name]) != tuple(actual[name]):
            problems.append(
                f"{name} has shape {tuple(actual[name])}, the header says {tuple(expected[name])}"
            )
    return "; ".join(problems)


# The flat layout the kernel reads: every linear layer's W^T [in, out] and bias in one
# float32 buffer, and one row (W^T offset, bias offset, in, out) per layer in the order
# below. A LayerNorm is a row too: (gamma offset, beta offset, 0, width).
_ARCH_CODES = {"tdrqn": 0, "ddrqn": 1}
# ints: the layout's counts and the options, by index.
_I_ARCH, _I_H, _I_PROJECT, _I_LAYERS, _I_HEADS, _I_ADV, _I_VALUE = range(7)
_I_DUELING, _I_TARGET_IN, _I_TARGET_V, _I_SIZE = 7, 8, 9, 10


def _layout(
    spec: PolicySpec, weights: Mapping[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(params float32, rows int64 [L, 4], ints int64, floats float64) for the kernel."""
    chunks: list[np.ndarray] = []
    rows: list[tuple[int, int, int, int]] = []
    size = 0

    def put(array: np.ndarray) -> int:
        nonlocal size
        offset = size
        chunks.append(np.ascontiguousarray(array, dtype=np.float32).ravel())
        size += array.size
        return offset

    def linear(weight: str, bias: str) -> None:
        w = weights[weight]  # [out, in]
        rows.append((put(w.T), put(weights[bias]), w.shape[1], w.shape[0]))  # W^T: [in, out]

    def norm(prefix: str) -> None:
        gamma = weights[prefix + ".weight"]
        rows.append((put(gamma), put(weights[prefix + ".bias"]), 0, gamma.shape[0]))

    linear("lstm.lstm.weight_ih_l0", "lstm.lstm.bias_ih_l0")
    linear("lstm.lstm.weight_hh_l0", "lstm.lstm.bias_hh_l0")
    project = spec.architecture == "tdrqn" and spec.lstm_hidden != spec.attn_width
    if spec.architecture == "tdrqn":
        if project:
            linear("mixer.project.weight", "mixer.project.bias")
        for layer in range(spec.attn_layers):
            prefix = f"mixer.encoder.layers.{layer}."
            linear(prefix + "self_attn.in_proj_weight", prefix + "self_attn.in_proj_bias")
            linear(prefix + "self_attn.out_proj.weight", prefix + "self_attn.out_proj.bias")
            norm(prefix + "norm1")
            linear(prefix + "linear1.weight", prefix + "linear1.bias")
            linear(prefix + "linear2.weight", prefix + "linear2.bias")
            norm(prefix + "norm2")
    else:
        linear("ff.0.weight", "ff.0.bias")
    linear("context.target.0.weight", "context.target.0.bias")
    linear("context.pattern.0.weight", "context.pattern.0.bias")
    for name, hidden in (("advantage", spec.head_hidden), ("value", spec.value_hidden)):
        for index in range(len(hidden) + 1):
            linear(f"head.{name}.{2 * index}.weight", f"head.{name}.{2 * index}.bias")
    ints = np.zeros(_I_SIZE, dtype=np.int64)
    ints[_I_ARCH] = _ARCH_CODES[spec.architecture]
    ints[_I_H] = spec.lstm_hidden
    ints[_I_PROJECT] = project
    ints[_I_LAYERS] = spec.attn_layers if spec.architecture == "tdrqn" else 0
    ints[_I_HEADS] = spec.attn_heads
    ints[_I_ADV] = len(spec.head_hidden) + 1
    ints[_I_VALUE] = len(spec.value_hidden) + 1
    ints[_I_DUELING] = spec.do_nothing_head == "dueling"
    ints[_I_TARGET_IN] = spec.target_in_input
    ints[_I_TARGET_V] = spec.target_voltage_in_input
    floats = np.array(
        [spec.v_rest_mV, spec.v_threshold_mV - spec.v_rest_mV, spec.layer_norm_eps],
        dtype=np.float64,
    )
    params = np.concatenate(chunks).astype(np.float32)
    return params, np.array(rows, dtype=np.int64), ints, floats


_JIT = dict(cache=True, nogil=True, fastmath={"contract"}, error_model="numpy")
"""No reassociation: each output sums its inputs in order, as a plain matrix product
does. Contraction lets mul + add become one FMA (rounding once instead of twice).
``error_model="numpy"``: a float division by zero gives inf as in NumPy instead of
raising, so divisions carry no branch and their loops vectorise (5x for the LSTM's
gates)."""


@numba.njit(**_JIT)
def _linear(params, row, x, y, relu, accumulate):  # pragma: no cover - compiled
    """y [m, out] (+)= x [m, in] @ W^T + b, then ReLU if ``relu``.

    Four inputs at a time are outermost, so their four weight rows [out] serve every
    token from the cache, and each output is loaded and stored once per four inputs
    (the loads and stores of y, not the arithmetic, bound a plain loop: this one is
    2-2.5x faster). The innermost loop runs along the output, contiguous and free of
    any reduction, so it vectorises without reassociation: each output still sums
    its inputs in order, then adds the bias.
    """
    w_offset, b_offset, n_in, n_out = row[0], row[1], row[2], row[3]
    weight = params[w_offset : w_offset + n_in * n_out].reshape((n_in, n_out))  # [in, out]
    bias = params[b_offset : b_offset + n_out]  # [out]
    m = x.shape[0]
    if not accumulate:
        for i in range(m):
            y[i, :] = 0.0
    k = 0
    while k + 4 <= n_in:
        w0, w1, w2, w3 = weight[k], weight[k + 1], weight[k + 2], weight[k + 3]  # [out] each
        for i in range(m):
            x0, x1, x2, x3 = x[i, k], x[i, k + 1], x[i, k + 2], x[i, k + 3]
            y_i = y[i]
            for j in range(n_out):
                y_i[j] = y_i[j] + x0 * w0[j] + x1 * w1[j] + x2 * w2[j] + x3 * w3[j]
        k += 4
    while k < n_in:
        w_k = weight[k]
        for i in range(m):
            x_ik, y_i = x[i, k], y[i]
            for j in range(n_out):
                y_i[j] += x_ik * w_k[j]
        k += 1
    for i in range(m):
        y_i = y[i]
        for j in range(n_out):
            value = y_i[j] + bias[j]
            y_i[j] = max(value, np.float32(0.0)) if relu else value


@numba.njit(**_JIT)
def _mlp(params, rows, first, count, x):  # pragma: no cover - compiled
    """Rows first..first+count-1 as Linear, ReLU, ..., Linear on x [m, in] → [m, out]."""
    current = x
    for r in range(first, first + count):
        out = np.empty((x.shape[0], rows[r, 3]), dtype=np.float32)
        _linear(params, rows[r], current, out, r < first + count - 1, False)
        current = out
    return current


@numba.njit(**_JIT)
def _add_and_norm(params, row, z, residual, eps):  # pragma: no cover - compiled
    """z [n, W] ← LayerNorm(z + residual), in place (post-norm)."""
    gamma = params[row[0] : row[0] + row[3]]
    beta = params[row[1] : row[1] + row[3]]
    width = z.shape[1]
    for i in range(z.shape[0]):
        total = 0.0
        for j in range(width):
            z[i, j] += residual[i, j]
            total += z[i, j]
        mean = total / width
        spread = 0.0
        for j in range(width):
            spread += (z[i, j] - mean) ** 2
        scale = 1.0 / math.sqrt(spread / width + eps)
        for j in range(width):
            z[i, j] = (z[i, j] - mean) * scale * gamma[j] + beta[j]


# tanh as Eigen's rational approximation (generic_fast_tanh_float): odd degree-13 over
# even degree-6 polynomials on [-7.9053, 7.9053], +-1 beyond. Unlike libm's tanhf it is
# plain arithmetic, so the LSTM's gate loops vectorise (the calls cost 2.5x the rest of
# the cell); its error is 3.5e-7 at most (checked on a dense grid in the tests).
_TANH_CLAMP = np.float32(7.90531110763549805)
_TANH_P = tuple(np.float32(a) for a in (
    4.89352455891786e-03, 6.37261928875436e-04, 1.48572235717979e-05, 5.12229709037114e-08,
    -8.60467152213735e-11, 2.00018790482477e-13, -2.76076847742355e-16,
))  # fmt: skip
_TANH_Q = tuple(np.float32(b) for b in (
    4.89352518554385e-03, 2.26843463243900e-03, 1.18534705686654e-04, 1.19825839466702e-06,
))  # fmt: skip
_HALF = np.float32(0.5)


@numba.njit(inline="always", **_JIT)
def _tanh(x):  # pragma: no cover - compiled
    x = min(max(x, -_TANH_CLAMP), _TANH_CLAMP)
    x2 = x * x
    p = _TANH_P[6]
    p = p * x2 + _TANH_P[5]
    p = p * x2 + _TANH_P[4]
    p = p * x2 + _TANH_P[3]
    p = p * x2 + _TANH_P[2]
    p = p * x2 + _TANH_P[1]
    p = p * x2 + _TANH_P[0]
    q = _TANH_Q[3]
    q = q * x2 + _TANH_Q[2]
    q = q * x2 + _TANH_Q[1]
    q = q * x2 + _TANH_Q[0]
    return x * p / q


@numba.njit(inline="always", **_JIT)
def _sigmoid(x):  # pragma: no cover - compiled
    return _HALF + _HALF * _tanh(_HALF * x)


@numba.njit(**_JIT)
def _attention(qkv, heads, out):  # pragma: no cover - compiled
    """Self-attention across the n tokens: qkv [n, 3W] → out [n, W] (heads concatenated)."""
    n, width = out.shape
    d = width // heads
    scale = np.float32(1.0 / math.sqrt(d))
    keys = np.empty((d, n), dtype=np.float32)  # one head's keys, transposed: [d, n]
    scores = np.empty(n, dtype=np.float32)  # one query's row
    for head in range(heads):
        q0, k0, v0 = head * d, width + head * d, 2 * width + head * d
        for j in range(n):
            for c in range(d):
                keys[c, j] = qkv[j, k0 + c]
        for i in range(n):
            scores[:] = 0.0
            for c in range(d):
                query = qkv[i, q0 + c] * scale
                for j in range(n):
                    scores[j] += query * keys[c, j]
            top = scores.max()
            total = np.float32(0.0)
            for j in range(n):
                scores[j] = math.exp(scores[j] - top)
                total += scores[j]
            out_i = out[i, q0 : q0 + d]
            out_i[:] = 0.0
            for j in range(n):
                p = scores[j] / total
                v_j = qkv[j, v0 : v0 + d]
                for c in range(d):
                    out_i[c] += p * v_j[c]


@numba.njit(**_JIT)
def _decide(
    params, rows, ints, floats, voltage, target, pattern, step, last_action, h, c, mask, q
):  # pragma: no cover - compiled
    """One decision: features → LSTM (h, c [n, H] updated in place) → mixing → context →
    heads → q [n+1] (filled) → the index of the best legal entry of q (-1 if none)."""
    n = voltage.shape[0]
    H = ints[_I_H]
    N = pattern.shape[0]
    # Per-neuron features x [n, F]: (V - V_r) / (V_th - V_r), stimulated at t-1, (is
    # target), (the target's normalised V).
    width = 2 + ints[_I_TARGET_IN] + ints[_I_TARGET_V]
    x = np.zeros((n, width), dtype=np.float32)
    v_rest, v_scale = np.float32(floats[0]), np.float32(floats[1])
    v_target = (voltage[target] - v_rest) / v_scale
    for i in range(n):
        x[i, 0] = (voltage[i] - v_rest) / v_scale
        x[i, 1] = 1.0 if i == last_action else 0.0
        column = 2
        if ints[_I_TARGET_IN]:
            x[i, column] = 1.0 if i == target else 0.0
            column += 1
        if ints[_I_TARGET_V]:
            x[i, column] = v_target
    # LSTM cell, gates [n, 4H] in PyTorch's order: input, forget, cell, output.
    gates = np.empty((n, 4 * H), dtype=np.float32)
    _linear(params, rows[0], x, gates, False, False)
    _linear(params, rows[1], h, gates, False, True)
    for i in range(n):
        for j in range(H):
            in_gate = _sigmoid(gates[i, j])
            forget = _sigmoid(gates[i, H + j])
            cell = _tanh(gates[i, 2 * H + j])
            out_gate = _sigmoid(gates[i, 3 * H + j])
            c[i, j] = forget * c[i, j] + in_gate * cell
            h[i, j] = out_gate * _tanh(c[i, j])
    # Mixing block → z [n, M].
    r = 2
    if ints[_I_ARCH] == 0:  # TDRQN: transformer encoder across the neurons, post-norm
        if ints[_I_PROJECT]:
            z = np.empty((n, rows[r, 3]), dtype=np.float32)
            _linear(params, rows[r], h, z, False, False)
            r += 1
        else:
            z = h.copy()
        W = z.shape[1]
        eps = floats[2]
        qkv = np.empty((n, 3 * W), dtype=np.float32)
        mixed = np.empty((n, W), dtype=np.float32)
        residual = np.empty((n, W), dtype=np.float32)
        for _ in range(ints[_I_LAYERS]):
            _linear(params, rows[r], z, qkv, False, False)
            _attention(qkv, ints[_I_HEADS], mixed)
            _linear(params, rows[r + 1], mixed, residual, False, False)
            _add_and_norm(params, rows[r + 2], z, residual, eps)
            hidden = np.empty((n, rows[r + 3, 3]), dtype=np.float32)
            _linear(params, rows[r + 3], z, hidden, True, False)
            _linear(params, rows[r + 4], hidden, residual, False, False)
            _add_and_norm(params, rows[r + 5], z, residual, eps)
            r += 6
    else:  # DDRQN: per-neuron FF + ReLU
        z = np.empty((n, rows[r, 3]), dtype=np.float32)
        _linear(params, rows[r], h, z, True, False)
        r += 1
    M = z.shape[1]
    # Context: the target's code (on for the target, off for the others) and the code of
    # the pattern shifted so step t comes first, padded with -1.
    E, P = rows[r, 3], rows[r + 1, 3]
    indicator = np.zeros((2, 1), dtype=np.float32)
    indicator[0, 0] = 1.0
    target_code = np.empty((2, E), dtype=np.float32)  # [on, off]
    _linear(params, rows[r], indicator, target_code, True, False)
    shifted = np.empty((1, N), dtype=np.float32)
    for k in range(N):
        shifted[0, k] = pattern[step + k] if step + k < N else -1.0
    pattern_code = np.empty((1, P), dtype=np.float32)
    _linear(params, rows[r + 1], shifted, pattern_code, True, False)
    r += 2
    U = M + E + P
    u = np.empty((n, U), dtype=np.float32)  # [z_i, target code_i, pattern code]
    for i in range(n):
        u[i, :M] = z[i]
        u[i, M : M + E] = target_code[0] if i == target else target_code[1]
        u[i, M + E :] = pattern_code[0]
    # Heads: one advantage per neuron; the do-nothing value from [mean_i u_i, u_target].
    advantage = _mlp(params, rows, r, ints[_I_ADV], u)  # [n, 1]
    r += ints[_I_ADV]
    pooled = np.empty((1, 2 * U), dtype=np.float32)
    for j in range(U):
        total = np.float32(0.0)
        for i in range(n):
            total += u[i, j]
        pooled[0, j] = total / np.float32(n)
        pooled[0, U + j] = u[target, j]
    value = _mlp(params, rows, r, ints[_I_VALUE], pooled)[0, 0]
    q[0] = value
    for i in range(n):
        q[i + 1] = advantage[i, 0] + value if ints[_I_DUELING] else advantage[i, 0]
    best = -1
    for j in range(n + 1):  # the first maximum among the legal entries, as argmax picks
        if mask[j] and (best < 0 or q[j] > q[best]):
            best = j
    return best


class CompiledPolicy:
    """A trained TDRQN or DDRQN as a NumPy/Numba policy for one environment.

    ``reset()`` forgets the episode (``act`` at step 0 also does); ``act(observation,
    info)`` returns the legal action of highest Q-value (-1 = do nothing, j = stimulate
    neuron j), as ``GreedyPolicy`` picks it from the PyTorch network, and advances the
    recurrent state. ``last_q`` holds that decision's Q-values [n + 1] (action + 1
    order). Runs on any n, like the network. Build one with :meth:`load` (a file from
    :func:`export_policy`) or :meth:`from_network`.
    """

    def __init__(self, spec: PolicySpec, weights: Mapping[str, np.ndarray], where: str) -> None:
        shapes = {name: tuple(array.shape) for name, array in weights.items()}
        expected = spec.weight_shapes()
        if shapes != expected:
            raise PolicyFileError(f"{where}: the weights {_mismatch(expected, shapes)}")
        self.spec = spec
        self._params, self._rows, self._ints, self._floats = _layout(spec, weights)
        self._h: np.ndarray | None = None
        self._c: np.ndarray | None = None
        self._q = np.zeros(0, dtype=np.float32)

    @classmethod
    def load(cls, path: str | Path, warm_up: bool = True) -> CompiledPolicy:
        """Read a file written by :func:`export_policy`, checked: an unreadable file, a
        foreign one, another format version, an unsupported architecture or weights that
        do not match the header raise :class:`PolicyFileError` naming the problem.

        ``warm_up`` makes one decision on a dummy observation so the kernel is compiled
        (or loaded from Numba's cache) here, not in the first real decision.
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"compiled policy file not found: {path}")
        if path.is_dir():
            raise PolicyFileError(f"{path} is a folder, not a compiled policy file")
        try:
            check_regular_file(path)  # a FIFO or a device would block or never end
        except OSError as error:
            raise PolicyFileError(
                f"{path} is not a compiled policy file: {error.strerror}"
            ) from None
        return cls._from_npz(path, str(path), warm_up)

    @classmethod
    def from_network(cls, network: Any, warm_up: bool = True) -> CompiledPolicy:
        """The compiled policy of a PyTorch TDRQN or DDRQN, through the very bytes
        :func:`export_policy` would write (nothing is written)."""
        return cls._from_npz(io.BytesIO(_policy_bytes(network)), "the exported network", warm_up)

    @classmethod
    def _from_npz(cls, source: Any, where: str, warm_up: bool) -> CompiledPolicy:
        try:
            with np.load(source, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except (zipfile.BadZipFile, OSError, ValueError, EOFError, zlib.error) as error:
            problem = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise PolicyFileError(
                f"{where} is not a readable compiled policy: {problem}"
            ) from error
        if HEADER_KEY not in arrays:
            raise PolicyFileError(f"{where} is not a compiled policy (no {HEADER_KEY!r} entry)")
        spec = _parse_header(where, arrays.pop(HEADER_KEY))
        bad = sorted(name for name, array in arrays.items() if array.dtype != np.float32)
        if bad:
            raise PolicyFileError(f"{where}: weights {bad} are not float32")
        bad = sorted(name for name, array in arrays.items() if not np.isfinite(array).all())
        if bad:
            raise PolicyFileError(f"{where}: weights {bad} hold NaN or infinite values")
        policy = cls(spec, arrays, where)
        if warm_up:
            policy.warm_up()
        return policy

    def warm_up(self) -> None:
        """One decision on a dummy observation (compiles the kernel), then ``reset``."""
        n, N = max(2, self.spec.n_neurons), self.spec.episode_length
        observation = dict(
            voltage=np.full(n, self.spec.v_rest_mV, dtype=np.float32),
            target=0, pattern=np.zeros(N, dtype=np.int8), step=0, last_action=-1,
        )  # fmt: skip
        self.act(observation, {"action_mask": np.ones(n + 1, dtype=bool)})
        self.reset()

    def reset(self) -> None:
        """Forget the episode: the next ``act`` starts from the zero state."""
        self._h = self._c = None

    @property
    def last_q(self) -> np.ndarray:
        """The Q-values of the last decision [n + 1] (a copy; empty before any)."""
        return self._q.copy()

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The legal action of highest Q-value for this observation (-1 = do nothing).

        ``observation`` is the single environment's dict (voltage [n], target, pattern
        [N], step, last_action), ``info["action_mask"]`` bool [n + 1]. Step 0 starts a
        new episode (zero state); a step other than 0 continues the current one.
        """
        voltage = np.ascontiguousarray(observation["voltage"], dtype=np.float32)
        pattern = np.ascontiguousarray(observation["pattern"], dtype=np.int8)
        mask = np.ascontiguousarray(info["action_mask"], dtype=np.bool_)
        target, step = int(observation["target"]), int(observation["step"])
        last_action = int(observation["last_action"])
        n, N = voltage.shape[0], self.spec.episode_length
        if voltage.ndim != 1 or pattern.shape != (N,) or mask.shape != (n + 1,):
            raise ValueError(
                f"CompiledPolicy.act: expected voltage [n], pattern [{N}] and action_mask "
                f"[n + 1]; got {voltage.shape}, {pattern.shape} and {mask.shape}"
            )
        if not (0 <= target < n and 0 <= step < N and -1 <= last_action < n):
            raise ValueError(
                f"CompiledPolicy.act: target {target}, step {step} or last_action "
                f"{last_action} out of range for n = {n}, N = {N} (the episode has {N} steps)"
            )
        if step == 0 or self._h is None:
            if step != 0:
                raise ValueError(
                    "CompiledPolicy.act: the policy must see the episode from step 0 "
                    f"(got step {step} after reset)"
                )
            self._h = np.zeros((n, self.spec.lstm_hidden), dtype=np.float32)  # [n, H]
            self._c = np.zeros((n, self.spec.lstm_hidden), dtype=np.float32)  # [n, H]
            self._q = np.zeros(n + 1, dtype=np.float32)
        elif self._h.shape[0] != n:
            raise ValueError(
                f"CompiledPolicy.act: the episode started with n = {self._h.shape[0]}, "
                f"this observation has n = {n}"
            )
        best = _decide(
            self._params, self._rows, self._ints, self._floats, voltage, target, pattern,
            step, last_action, self._h, self._c, mask, self._q,
        )  # fmt: skip
        if best < 0:
            raise ValueError("CompiledPolicy.act: the action mask allows no action")
        return best - 1


def _parse_header(where: str, raw: np.ndarray) -> PolicySpec:
    try:
        header = json.loads(str(raw))
    except (json.JSONDecodeError, TypeError) as error:
        raise PolicyFileError(f"{where} has an unreadable header: {error}") from error
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise PolicyFileError(f"{where} is not a compiled policy (no {FORMAT_NAME} header)")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise PolicyFileError(
            f"{where} has compiled-policy format version {version}; this spikectl reads "
            f"version {FORMAT_VERSION} (export the network again with export_policy)"
        )
    if header.get("architecture") not in SUPPORTED_ARCHITECTURES:
        raise PolicyFileError(
            f"{where} holds architecture {header.get('architecture')!r}; supported: "
            f"{', '.join(SUPPORTED_ARCHITECTURES)}"
        )
    names = [field.name for field in fields(PolicySpec)]
    missing = [name for name in names if name not in header]
    if missing:
        raise PolicyFileError(f"{where}: the header lacks {missing}")
    values = {name: header[name] for name in names}
    for field in fields(PolicySpec):
        value = values[field.name]
        if field.type == "int":
            ok = type(value) is int and value >= 1
        elif field.type == "float":
            ok = type(value) in (int, float) and math.isfinite(value)
        elif field.type == "bool":
            ok = type(value) is bool
        elif field.type == "tuple[int, ...]":
            ok = isinstance(value, list) and all(type(v) is int and v >= 1 for v in value)
            value = tuple(value) if ok else value
        else:
            ok = isinstance(value, str)
        if not ok:
            raise PolicyFileError(f"{where}: the header's {field.name} is {value!r}")
        values[field.name] = value
    if values["do_nothing_head"] not in ("dueling", "pooled"):
        raise PolicyFileError(
            f"{where}: do_nothing_head {values['do_nothing_head']!r} is not 'dueling' or 'pooled'"
        )
    if values["attn_width"] % values["attn_heads"] or values["layer_norm_eps"] <= 0:
        raise PolicyFileError(
            f"{where}: attn_heads {values['attn_heads']} must divide attn_width "
            f"{values['attn_width']}, and layer_norm_eps {values['layer_norm_eps']} be > 0"
        )
    if values["v_threshold_mV"] == values["v_rest_mV"]:
        raise PolicyFileError(f"{where}: v_threshold_mV equals v_rest_mV")
    return PolicySpec(**values)
