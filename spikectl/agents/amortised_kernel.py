"""The amortised belief's step without PyTorch: what a controller runs every millisecond.

:class:`AmortisedBelief.step <spikectl.agents.amortised_belief.AmortisedBelief.step>`
in PyTorch's eager mode spends most of its 0.6-0.9 ms a step dispatching a few dozen
tiny operators; the same arithmetic in NumPy on one network's [n, D] arrays takes a
fraction of that (docs/results/amortised-controller). :class:`BeliefKernel` copies a
trained belief's weights once and computes, step by step, the same logits
(float32; equal to PyTorch's within rounding, ``tests/test_amortised_controller.py``).
:class:`BeliefFeatureTracker` computes one step's row of
:func:`~spikectl.agents.amortised_belief.belief_features` from that step's observation
in O(n), where ``belief_features`` recomputes the whole history.

Shapes in comments: n neurons, F features, D width, h heads.
"""

from __future__ import annotations

import math

import numpy as np

from spikectl.agents.amortised_belief import AmortisedBelief
from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.neuron.params import NeuronParams

_LAYER_NORM_EPS = 1e-5  # PyTorch's TransformerEncoderLayer default
_PRIOR_FLOOR = 1e-4  # prior_logits' clip


def _erf(x: np.ndarray) -> np.ndarray:
    """erf by Abramowitz and Stegun 7.1.26 (absolute error below 1.5e-7: far below
    float32's rounding of the activations it feeds); NumPy has no erf of its own."""
    sign = np.sign(x)
    a = np.abs(x)
    t = 1.0 / (1.0 + 0.3275911 * a)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                     + t * 1.061405429))))  # fmt: skip
    return sign * (1.0 - poly * np.exp(-a * a))


def _gelu(x: np.ndarray) -> np.ndarray:
    return 0.5 * x * (1.0 + _erf(x * np.float32(1.0 / math.sqrt(2.0))))


def _layer_norm(x: np.ndarray, gamma: np.ndarray, beta: np.ndarray) -> np.ndarray:
    mean = x.mean(axis=-1, keepdims=True)
    centred = x - mean
    variance = (centred * centred).mean(axis=-1, keepdims=True)
    return centred / np.sqrt(variance + _LAYER_NORM_EPS) * gamma + beta


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


class BeliefKernel:
    """One network's belief, step by step, in NumPy: ``reset(n)`` at an episode's start,
    then ``step(features [n, F]) -> logits [n, 3]`` over
    :data:`~spikectl.agents.amortised_belief.CLASSES` (prior logits included), as
    ``AmortisedBelief.step`` with a batch of one."""

    def __init__(self, model: AmortisedBelief) -> None:
        weights = {key: value.detach().cpu().numpy().astype(np.float32)
                   for key, value in model.state_dict().items()}  # fmt: skip
        self.width, self.heads = model.width, model.heads

        def linear(prefix: str, weight: str = "weight", bias: str = "bias"):
            return weights[f"{prefix}.{weight}"].T.copy(), weights[f"{prefix}.{bias}"]

        self.encode = (linear("encode.0"), linear("encode.2"))
        self.gru_input = linear("memory", "weight_ih_l0", "bias_ih_l0")  # [D, 3D], [3D]
        self.gru_hidden = linear("memory", "weight_hh_l0", "bias_hh_l0")
        self.mix = [
            {
                "in": linear(f"mix.{k}.self_attn", "in_proj_weight", "in_proj_bias"),
                "out": linear(f"mix.{k}.self_attn.out_proj"),
                "ff1": linear(f"mix.{k}.linear1"),
                "ff2": linear(f"mix.{k}.linear2"),
                "norm1": (weights[f"mix.{k}.norm1.weight"], weights[f"mix.{k}.norm1.bias"]),
                "norm2": (weights[f"mix.{k}.norm2.weight"], weights[f"mix.{k}.norm2.bias"]),
            }
            for k in range(model.mix_layers)
        ]
        self.head = (linear("head.0"), linear("head.2"))
        self.hidden = self.prior = np.zeros((0, 0), dtype=np.float32)

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
        (w1, b1), (w2, b2) = self.encode
        x = _gelu(_gelu(features @ w1 + b1) @ w2 + b2)  # [n, D]
        h = self.hidden
        d = self.width
        gates_x = x @ self.gru_input[0] + self.gru_input[1]  # [n, 3D]: r, z, new
        gates_h = h @ self.gru_hidden[0] + self.gru_hidden[1]  # [n, 3D]
        reset = _sigmoid(gates_x[:, :d] + gates_h[:, :d])
        update = _sigmoid(gates_x[:, d:2 * d] + gates_h[:, d:2 * d])
        new = np.tanh(gates_x[:, 2 * d:] + reset * gates_h[:, 2 * d:])
        memory = (1.0 - update) * new + update * h  # [n, D]
        self.hidden = memory
        mixed = memory
        for layer in self.mix:
            mixed = self._mix(mixed, layer)
        (w3, b3), (w4, b4) = self.head
        joined = np.concatenate([memory, mixed], axis=1)  # [n, 2D]
        return _gelu(joined @ w3 + b3) @ w4 + b4 + self.prior  # [n, 3]

    def _mix(self, x: np.ndarray, layer: dict) -> np.ndarray:
        """One post-norm transformer encoder layer (ReLU feed-forward), as PyTorch's."""
        n, d, heads = x.shape[0], self.width, self.heads
        per_head = d // heads
        qkv = x @ layer["in"][0] + layer["in"][1]  # [n, 3D]
        q, k, v = (qkv[:, i * d:(i + 1) * d].reshape(n, heads, per_head).transpose(1, 0, 2)
                   for i in range(3))  # fmt: skip  # each [h, n, D/h]
        scores = (q @ k.transpose(0, 2, 1)) * np.float32(1.0 / math.sqrt(per_head))  # [h, n, n]
        scores = np.exp(scores - scores.max(axis=-1, keepdims=True))
        attention = scores / scores.sum(axis=-1, keepdims=True)
        attended = (attention @ v).transpose(1, 0, 2).reshape(n, d)  # [n, D]
        x = _layer_norm(x + attended @ layer["out"][0] + layer["out"][1], *layer["norm1"])
        hidden = np.maximum(x @ layer["ff1"][0] + layer["ff1"][1], 0.0)  # [n, 2D]
        return _layer_norm(x + hidden @ layer["ff2"][0] + layer["ff2"][1], *layer["norm2"])


def target_prior(n_neurons: int, target: int) -> np.ndarray:
    """[n] the generator's P(i -> target) by distance, 0 for the target itself."""
    neurons = np.arange(n_neurons)
    prior = connection_probability(np.abs(neurons - target)).astype(np.float64)
    prior[target] = 0.0
    return prior


class BeliefFeatureTracker:
    """:func:`~spikectl.agents.amortised_belief.belief_features` one step at a time, for
    one episode: ``row(voltage [n], action)`` after each step gives that step's [n, F]
    row, from the running state ``belief_features`` keeps over the whole history."""

    def __init__(self, n_neurons: int, target: int, params: NeuronParams) -> None:
        self.params, self.n, self.target = params, n_neurons, target
        self.neurons = np.arange(n_neurons)
        interval = params.min_release_interval_steps
        self.since = np.full(n_neurons, interval, dtype=np.int64)  # rested
        self.after_reset = np.full(n_neurons, params.v_rest_mV)
        self.refractory_left = np.zeros(n_neurons, dtype=np.int64)
        self.released = np.zeros(n_neurons)  # this step's releases (float 0/1)
        self.sums = np.zeros((5, n_neurons))  # alone count, alone sum, count, sum, others
        self.static = np.zeros((n_neurons, 2))
        self.static[target, 0] = 1.0  # is_target
        self.static[:, 1] = target_prior(n_neurons, target)
        self.last_spikes = np.zeros(n_neurons, dtype=bool)

    def row(self, voltage: np.ndarray, action: int) -> np.ndarray:
        """float32 [n, F]: the features of the step whose action was ``action`` and
        whose observed potentials (after integration, before reset) are ``voltage``."""
        p = self.params
        voltage = np.asarray(voltage, dtype=np.float64)
        spikes = voltage >= p.v_spike_mV
        released_before = self.released
        self.since = np.minimum(self.since + 1, p.min_release_interval_steps)
        released = spikes & (self.since >= p.min_release_interval_steps)
        self.since[released] = 0
        self.released = released.astype(np.float64)
        stimulated = (self.neurons == action).astype(np.float64)
        predicted = (self.after_reset - (self.after_reset - p.v_rest_mV) * p.leak_per_step
                     + stimulated * p.stimulus_step_mV)  # fmt: skip
        observed = self.refractory_left == 0
        residual = np.where(observed, (voltage - predicted) / p.synaptic_step_mV, 0.0)
        self.after_reset = np.where(spikes | ~observed, p.v_rest_mV, voltage)
        self.refractory_left = np.where(spikes, p.refractory_steps,
                                        np.maximum(self.refractory_left - 1, 0))  # fmt: skip
        self.last_spikes = spikes
        t_observed = float(observed[self.target])
        t_residual = residual[self.target] * t_observed
        others = released_before.sum() - released_before
        seen = released_before * t_observed
        alone = seen * (others == 0)
        self.sums += np.stack([alone, alone * t_residual, seen, seen * t_residual, seen * others])
        alone_count, alone_sum, count, residual_sum, others_sum = self.sums
        seen_residual = residual * observed
        others_residual = seen_residual.sum() - seen_residual
        n = self.n
        columns = (
            stimulated, spikes, np.clip((voltage - p.v_rest_mV) / p.synaptic_step_mV, -2.0, 3.0),
            released_before, self.static[:, 0], self.static[:, 1], np.full(n, t_residual),
            np.full(n, t_observed), released_before * t_residual, seen, others,
            released_before * np.clip(others_residual, -4.0, 4.0),
            np.minimum(alone_count, 3.0) / 3.0,
            np.clip(alone_sum / np.maximum(alone_count, 1.0), -2.0, 2.0),
            np.minimum(count, 5.0) / 5.0,
            np.clip(residual_sum / np.maximum(count, 1.0), -4.0, 4.0),
            np.minimum(others_sum / np.maximum(count, 1.0), 8.0) / 8.0,
        )
        return np.stack(columns, axis=-1).astype(np.float32)  # [n, F]
