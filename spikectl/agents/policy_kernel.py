"""The compiled policy's per-step forward (``spikectl.agents.compiled``): the weights in
one flat float32 buffer (:func:`_layout`) and the Numba functions that read it, ending
in :func:`_decide`, one environment step of the network and its masked greedy action.

Shapes in comments: n neurons, N episode length, F per-neuron input features, H LSTM
width, W attention width, M mixing output width, E / P target / pattern code widths,
U = M + E + P head input width.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numba
import numpy as np

from spikectl.agents.policy_file import PolicySpec
from spikectl.agents.spikes import VISIBLE_SPIKE_LEVEL
from spikectl.contexts.generation import (
    CONNECTION_PROBABILITY_BANDS,
    LONG_RANGE_CONNECTION_PROBABILITY,
)

_ARCH_CODES = {"tdrqn": 0, "ddrqn": 1}
# ints: the layout's counts and the options, by index.
_I_ARCH, _I_H, _I_PROJECT, _I_LAYERS, _I_HEADS, _I_ADV, _I_VALUE = range(7)
_I_DUELING, _I_TARGET_IN, _I_TARGET_V, _I_OTHERS, _I_PROXIMITY, _I_SIZE = 7, 8, 9, 10, 11, 12
# The generator's bands (largest distance, probability) as arrays the kernel can read.
_BAND_DISTANCES = np.array([d for d, _ in CONNECTION_PROBABILITY_BANDS], dtype=np.float32)
_BAND_PROBABILITIES = np.array([p for _, p in CONNECTION_PROBABILITY_BANDS], dtype=np.float32)


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
    ints[_I_OTHERS] = spec.others_spiking_in_input
    ints[_I_PROXIMITY] = spec.proximity_in_input
    floats = np.array(
        [spec.v_rest_mV, spec.v_threshold_mV - spec.v_rest_mV, spec.layer_norm_eps,
         VISIBLE_SPIKE_LEVEL],
        dtype=np.float64,
    )  # fmt: skip
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
    params,
    rows,
    ints,
    floats,
    voltage,
    position,
    target,
    pattern,
    step,
    last_action,
    h,
    c,
    mask,
    q,
):  # pragma: no cover - compiled
    """One decision: features → LSTM (h, c [n, H] updated in place) → mixing → context →
    heads → q [n+1] (filled) → the index of the best legal entry of q (-1 if none)."""
    n = voltage.shape[0]
    H = ints[_I_H]
    N = pattern.shape[0]
    # Per-neuron features x [n, F]: (V - V_r) / (V_th - V_r), stimulated at t-1, (is
    # target), (the target's normalised V), (how many other neurons show a spike), (the
    # generator's prior of a synapse onto the target at its distance; 0 at the target).
    width = 2 + ints[_I_TARGET_IN] + ints[_I_TARGET_V] + ints[_I_OTHERS] + ints[_I_PROXIMITY]
    x = np.zeros((n, width), dtype=np.float32)
    v_rest, v_scale = np.float32(floats[0]), np.float32(floats[1])
    spike_level = np.float32(floats[3])
    v_target = (voltage[target] - v_rest) / v_scale
    for i in range(n):
        x[i, 0] = (voltage[i] - v_rest) / v_scale
    spiking = 0
    if ints[_I_OTHERS]:
        for i in range(n):
            spiking += x[i, 0] >= spike_level
    for i in range(n):
        x[i, 1] = 1.0 if i == last_action else 0.0
        column = 2
        if ints[_I_TARGET_IN]:
            x[i, column] = 1.0 if i == target else 0.0
            column += 1
        if ints[_I_TARGET_V]:
            x[i, column] = v_target
            column += 1
        if ints[_I_OTHERS]:
            x[i, column] = spiking - (x[i, 0] >= spike_level)
            column += 1
        if ints[_I_PROXIMITY]:
            distance = abs(position[i] - position[target])
            proximity = np.float32(LONG_RANGE_CONNECTION_PROBABILITY)
            for band in range(_BAND_DISTANCES.shape[0] - 1, -1, -1):
                if distance <= _BAND_DISTANCES[band]:
                    proximity = _BAND_PROBABILITIES[band]
            x[i, column] = 0.0 if distance == 0 else proximity
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
