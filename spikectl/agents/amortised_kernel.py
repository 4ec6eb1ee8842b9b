"""The amortised belief's step compiled: what a controller runs every millisecond.

:class:`AmortisedBelief.step <spikectl.agents.amortised_belief.AmortisedBelief.step>`
in PyTorch's eager mode spends most of its 0.6-0.9 ms a step dispatching a few dozen
tiny operators. :class:`BeliefKernel` copies a trained belief's weights once and runs
the same arithmetic on one network's [n, D] arrays in one Numba function (float32;
equal to PyTorch's within rounding, ``tests/test_amortised_controller.py``).
:class:`BeliefFeatureTracker` computes one step's row of
:func:`~spikectl.agents.amortised_belief.belief_features` from that step's observation
in O(n), where ``belief_features`` recomputes the whole history.

Shapes in comments: n neurons, F features, D width, L mixing layers.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spikectl.agents.amortised_belief import N_FEATURES, AmortisedBelief
from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.neuron.params import NeuronParams

_LAYER_NORM_EPS = 1e-5  # PyTorch's TransformerEncoderLayer default
_PRIOR_FLOOR = 1e-4  # prior_logits' clip
_JIT = dict(cache=True, nogil=True, fastmath={"contract"}, error_model="numpy")


@numba.njit(**_JIT)
def _linear(x, weight, bias, out):  # pragma: no cover (compiled)
    """out [n, O] = x [n, I] @ weight [I, O] + bias [O]; the inner loop runs along O."""
    for row in range(x.shape[0]):
        out[row, :] = bias
        for k in range(x.shape[1]):
            value = x[row, k]
            for j in range(weight.shape[1]):
                out[row, j] += value * weight[k, j]


@numba.njit(**_JIT)
def _gelu(x):  # pragma: no cover (compiled)
    """In place: GELU, erf form (PyTorch's nn.GELU default)."""
    root_half = 1.0 / math.sqrt(2.0)
    for row in range(x.shape[0]):
        for j in range(x.shape[1]):
            value = x[row, j]
            x[row, j] = 0.5 * value * (1.0 + math.erf(value * root_half))


@numba.njit(**_JIT)
def _add_norm(x, residual, gamma, beta):  # pragma: no cover (compiled)
    """In place: x = LayerNorm(x + residual) over the last axis."""
    width = x.shape[1]
    for row in range(x.shape[0]):
        mean = 0.0
        for j in range(width):
            x[row, j] += residual[row, j]
            mean += x[row, j]
        mean /= width
        variance = 0.0
        for j in range(width):
            variance += (x[row, j] - mean) ** 2
        scale = 1.0 / math.sqrt(variance / width + _LAYER_NORM_EPS)
        for j in range(width):
            x[row, j] = (x[row, j] - mean) * scale * gamma[j] + beta[j]


@numba.njit(**_JIT)
def _attend(qkv, heads, out):  # pragma: no cover (compiled)
    """out [n, D]: multi-head self-attention of qkv [n, 3D] (q, k, v side by side). The
    keys are transposed first so that the scores' inner loop runs along contiguous memory."""
    n, width = out.shape
    size = width // heads
    scale = 1.0 / math.sqrt(size)
    keys = np.ascontiguousarray(qkv[:, width : 2 * width].T)  # [D, n]
    scores = np.empty((n, n), dtype=np.float32)
    out[:, :] = 0.0
    for head in range(heads):
        base = head * size
        scores[:, :] = 0.0
        for i in range(n):
            for c in range(base, base + size):
                query = qkv[i, c] * scale
                for j in range(n):
                    scores[i, j] += query * keys[c, j]
        for i in range(n):
            top = scores[i].max()
            norm = 0.0
            for j in range(n):
                scores[i, j] = math.exp(scores[i, j] - top)
                norm += scores[i, j]
            for j in range(n):
                scores[i, j] /= norm
        for i in range(n):
            for j in range(n):
                weight = scores[i, j]
                for c in range(base, base + size):
                    out[i, c] += weight * qkv[j, 2 * width + c]


@numba.njit(**_JIT)
def _step(features, hidden, heads, prior, w):  # pragma: no cover (compiled)
    """Logits [n, 3] of one step; ``hidden`` [n, D] (the GRU's memory) updated in place.
    ``w``: the weights as :meth:`BeliefKernel.__init__` packs them."""
    (enc1_w, enc1_b, enc2_w, enc2_b, gi_w, gi_b, gh_w, gh_b, in_w, in_b, out_w, out_b,
     ff1_w, ff1_b, ff2_w, ff2_b, norm1, norm2, head1_w, head1_b, head2_w, head2_b) = w  # fmt: skip
    n, width = hidden.shape
    f32 = np.float32
    first = np.empty((n, width), dtype=f32)
    _linear(features, enc1_w, enc1_b, first)
    _gelu(first)
    x = np.empty((n, width), dtype=f32)
    _linear(first, enc2_w, enc2_b, x)
    _gelu(x)
    gates_x = np.empty((n, 3 * width), dtype=f32)
    gates_h = np.empty((n, 3 * width), dtype=f32)
    _linear(x, gi_w, gi_b, gates_x)
    _linear(hidden, gh_w, gh_b, gates_h)
    for i in range(n):
        for j in range(width):
            reset = 1.0 / (1.0 + math.exp(-(gates_x[i, j] + gates_h[i, j])))
            update = 1.0 / (1.0 + math.exp(-(gates_x[i, width + j] + gates_h[i, width + j])))
            new = math.tanh(gates_x[i, 2 * width + j] + reset * gates_h[i, 2 * width + j])
            hidden[i, j] = (1.0 - update) * new + update * hidden[i, j]
    joined = np.empty((n, 2 * width), dtype=f32)  # [memory, mixed]
    joined[:, :width] = hidden
    mixed = hidden.copy()
    qkv = np.empty((n, 3 * width), dtype=f32)
    attended = np.empty((n, width), dtype=f32)
    projected = np.empty((n, width), dtype=f32)
    inner = np.empty((n, ff1_w.shape[2]), dtype=f32)
    for layer in range(in_w.shape[0]):
        _linear(mixed, in_w[layer], in_b[layer], qkv)
        _attend(qkv, heads, attended)
        _linear(attended, out_w[layer], out_b[layer], projected)
        _add_norm(mixed, projected, norm1[layer, 0], norm1[layer, 1])
        _linear(mixed, ff1_w[layer], ff1_b[layer], inner)
        for i in range(n):
            for j in range(inner.shape[1]):
                inner[i, j] = max(inner[i, j], 0.0)
        _linear(inner, ff2_w[layer], ff2_b[layer], projected)
        _add_norm(mixed, projected, norm2[layer, 0], norm2[layer, 1])
    joined[:, width:] = mixed
    head = np.empty((n, width), dtype=f32)
    _linear(joined, head1_w, head1_b, head)
    _gelu(head)
    logits = np.empty((n, 3), dtype=f32)
    _linear(head, head2_w, head2_b, logits)
    return logits + prior


class BeliefKernel:
    """One network's belief, step by step, compiled: ``reset(prior [n])`` at an episode's
    start, then ``step(features [n, F]) -> logits [n, 3]`` over
    :data:`~spikectl.agents.amortised_belief.CLASSES` (prior logits included), as
    ``AmortisedBelief.step`` with a batch of one."""

    def __init__(self, model: AmortisedBelief) -> None:
        state = {key: value.detach().cpu().numpy().astype(np.float32)
                 for key, value in model.state_dict().items()}  # fmt: skip
        self.width, self.heads = model.width, model.heads
        layers = range(model.mix_layers)

        def transposed(name: str) -> np.ndarray:  # [out, in] -> [in, out]
            return np.ascontiguousarray(state[name].T)

        def stacked(name: str, transpose: bool = True) -> np.ndarray:  # [L, ...]
            shape = (0, self.width, self.width) if transpose else (0, self.width)
            arrays = [transposed(f"mix.{k}.{name}") if transpose else state[f"mix.{k}.{name}"]
                      for k in layers]  # fmt: skip
            return np.ascontiguousarray(np.stack(arrays)) if arrays else np.zeros(shape, np.float32)

        def norms(name: str) -> np.ndarray:  # [L, 2, D]: gamma, beta
            pairs = [np.stack([state[f"mix.{k}.{name}.weight"], state[f"mix.{k}.{name}.bias"]])
                     for k in layers]  # fmt: skip
            return np.stack(pairs) if pairs else np.zeros((0, 2, self.width), np.float32)

        self.weights = (
            transposed("encode.0.weight"), state["encode.0.bias"],
            transposed("encode.2.weight"), state["encode.2.bias"],
            transposed("memory.weight_ih_l0"), state["memory.bias_ih_l0"],
            transposed("memory.weight_hh_l0"), state["memory.bias_hh_l0"],
            stacked("self_attn.in_proj_weight"), stacked("self_attn.in_proj_bias", False),
            stacked("self_attn.out_proj.weight"), stacked("self_attn.out_proj.bias", False),
            stacked("linear1.weight"), stacked("linear1.bias", False),
            stacked("linear2.weight"), stacked("linear2.bias", False),
            norms("norm1"), norms("norm2"),
            transposed("head.0.weight"), state["head.0.bias"],
            transposed("head.2.weight"), state["head.2.bias"],
        )  # fmt: skip
        self.hidden = self.prior = np.zeros((0, 3), dtype=np.float32)

    def reset(self, prior: np.ndarray) -> None:
        """A new episode whose prior [n] P(i -> target) is ``prior`` (0 for the target):
        the GRU's memory at zero, and the prior's logits, added to every step's as
        ``prior_logits`` computes them."""
        p = np.clip(prior, _PRIOR_FLOOR, 1.0 - _PRIOR_FLOOR)
        self.prior = np.stack([np.log1p(-p), np.log(p * EXCITATORY_PROBABILITY),
                               np.log(p * (1.0 - EXCITATORY_PROBABILITY))],
                              axis=-1).astype(np.float32)  # fmt: skip  # [n, 3]
        self.hidden = np.zeros((p.shape[0], self.width), dtype=np.float32)  # [n, D]

    def step(self, features: np.ndarray) -> np.ndarray:
        """features float32 [n, F] of this step -> logits float32 [n, 3]."""
        features = np.ascontiguousarray(features, dtype=np.float32)
        return _step(features, self.hidden, self.heads, self.prior, self.weights)


def target_prior(n_neurons: int, target: int) -> np.ndarray:
    """[n] the generator's P(i -> target) by distance, 0 for the target itself."""
    neurons = np.arange(n_neurons)
    prior = connection_probability(np.abs(neurons - target)).astype(np.float64)
    prior[target] = 0.0
    return prior


@numba.njit(**_JIT)
def _track(voltage, action, target, state, sums, prior, constants, out):  # pragma: no cover
    """One step of :class:`BeliefFeatureTracker`: ``state`` [4, n] (steps since the last
    release, the potential after the last reset, refractory steps left, the releases of
    the step before) and ``sums`` [5, n] (the running evidence) updated in place, the
    step's features written to ``out`` [n, F]."""
    v_spike, interval, v_rest, leak, stimulus, synaptic, refractory = constants
    n = voltage.shape[0]
    target_observed = 1.0 if state[2, target] == 0 else 0.0
    target_residual = 0.0
    if target_observed > 0:
        after = state[1, target]
        kick = stimulus if action == target else 0.0
        target_residual = (voltage[target] - (after - (after - v_rest) * leak + kick)) / synaptic
    released_total = 0.0
    seen_residual_total = 0.0
    residual = np.empty(n)
    for i in range(n):
        released_total += state[3, i]
        after = state[1, i]
        kick = stimulus if action == i else 0.0
        residual[i] = 0.0
        if state[2, i] == 0:
            residual[i] = (voltage[i] - (after - (after - v_rest) * leak + kick)) / synaptic
        seen_residual_total += residual[i]
    for i in range(n):
        before = state[3, i]
        others = released_total - before
        seen = before * target_observed
        alone = seen if others == 0 else 0.0
        sums[0, i] += alone
        sums[1, i] += alone * target_residual
        sums[2, i] += seen
        sums[3, i] += seen * target_residual
        sums[4, i] += seen * others
        spiked = voltage[i] >= v_spike
        out[i, 0] = 1.0 if action == i else 0.0
        out[i, 1] = 1.0 if spiked else 0.0
        out[i, 2] = min(max((voltage[i] - v_rest) / synaptic, -2.0), 3.0)
        out[i, 3] = before
        out[i, 4] = 1.0 if i == target else 0.0
        out[i, 5] = prior[i]
        out[i, 6] = target_residual
        out[i, 7] = target_observed
        out[i, 8] = before * target_residual
        out[i, 9] = seen
        out[i, 10] = others
        out[i, 11] = before * min(max(seen_residual_total - residual[i], -4.0), 4.0)
        out[i, 12] = min(sums[0, i], 3.0) / 3.0
        out[i, 13] = min(max(sums[1, i] / max(sums[0, i], 1.0), -2.0), 2.0)
        out[i, 14] = min(sums[2, i], 5.0) / 5.0
        out[i, 15] = min(max(sums[3, i] / max(sums[2, i], 1.0), -4.0), 4.0)
        out[i, 16] = min(sums[4, i] / max(sums[2, i], 1.0), 8.0) / 8.0
        # The state for the next step: releases by the vesicle rule, resets, refractoriness.
        since = min(state[0, i] + 1.0, interval)
        released = spiked and since >= interval
        state[0, i] = 0.0 if released else since
        state[3, i] = 1.0 if released else 0.0
        observed = state[2, i] == 0
        state[1, i] = v_rest if (spiked or not observed) else voltage[i]
        state[2, i] = refractory if spiked else max(state[2, i] - 1.0, 0.0)


class BeliefFeatureTracker:
    """:func:`~spikectl.agents.amortised_belief.belief_features` one step at a time, for
    one episode: ``row(voltage [n], action)`` after each step gives that step's [n, F]
    row, from the running state ``belief_features`` keeps over the whole history
    (compiled: O(n) a step)."""

    def __init__(self, n_neurons: int, target: int, params: NeuronParams) -> None:
        self.params, self.n, self.target = params, n_neurons, int(target)
        self.state = np.zeros((4, n_neurons))  # since, after_reset, refractory_left, released
        self.state[0] = params.min_release_interval_steps  # rested: the first spike releases
        self.state[1] = params.v_rest_mV
        self.sums = np.zeros((5, n_neurons))  # alone count, alone sum, count, sum, others
        self.prior = target_prior(n_neurons, target)
        self.constants = (
            float(params.v_spike_mV), float(params.min_release_interval_steps),
            float(params.v_rest_mV), float(params.leak_per_step),
            float(params.stimulus_step_mV), float(params.synaptic_step_mV),
            float(params.refractory_steps),
        )  # fmt: skip

    @property
    def since(self) -> np.ndarray:
        """[n] steps since each neuron's last release (saturating at the interval)."""
        return self.state[0]

    @property
    def after_reset(self) -> np.ndarray:
        """[n] each neuron's potential after the last step's reset (mV)."""
        return self.state[1]

    @property
    def refractory_left(self) -> np.ndarray:
        """[n] refractory steps left: a neuron with any is held at rest this step."""
        return self.state[2]

    def row(self, voltage: np.ndarray, action: int) -> np.ndarray:
        """float32 [n, F]: the features of the step whose action was ``action`` and
        whose observed potentials (after integration, before reset) are ``voltage``."""
        out = np.empty((self.n, N_FEATURES), dtype=np.float32)
        _track(np.asarray(voltage, dtype=np.float64), int(action), self.target, self.state,
               self.sums, self.prior, self.constants, out)  # fmt: skip
        return out
