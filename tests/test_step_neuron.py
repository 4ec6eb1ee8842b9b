"""The kernel's per-network and per-neuron steps, which the compiled beam search calls
(spikectl.neuron.kernel: step_network, step_neuron, predict_neuron): the planner's
shortcuts through them equal the whole step bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl import NeuronParams
from spikectl.neuron.kernel import (
    kernel_constants,
    predict_neuron,
    step_constants,
    step_network,
    step_neuron,
)
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance


def random_states(rng, batch: int, n: int, params: NeuronParams) -> SimulatorState:
    state = SimulatorState.at_rest(batch, n, params)
    state.voltage_mV[:] = params.v_rest_mV + rng.uniform(-10.0, 25.0, (batch, n))
    state.refractory_left[:] = rng.integers(0, 2, (batch, n)) * params.refractory_steps
    state.steps_since_release[:] = rng.choice([0, 1, 3, 5, 9, 2**30], (batch, n))
    state.released[:] = rng.random((batch, n)) < 0.4
    return state


def networks(rng, n: int):
    signs = rng.choice([-1, 0, 0, 1], (n, n)).astype(np.int8)
    np.fill_diagonal(signs, 0)
    yield signs
    yield np.round(signs * rng.uniform(0.5, 1.5, (n, n)), 2)  # float weights (estimates)


def one_step(weights, state, b, action, constants, neurons):
    """step_network on a copy of network b: (state after, voltage out, spikes out)."""
    n = weights.shape[0]
    v, r = state.voltage_mV[b].copy(), state.refractory_left[b].copy()
    since, x = state.steps_since_release[b].copy(), state.released[b].copy()
    synaptic = np.empty(n)
    out_v, out_s = np.empty((1, 1, n)), np.empty((1, 1, n), dtype=bool)
    step_network(weights, action, v, r, since, x, synaptic, step_constants(constants), out_v,
                 out_s, 0, 0, neurons[0], neurons[1], None, None)  # fmt: skip
    return (v, r, since, x), out_v[0, 0], out_s[0, 0], synaptic


@pytest.mark.parametrize("heterogeneous", [False, True])
def test_step_network_is_advance(heterogeneous):
    rng = np.random.default_rng(1)
    params, n = NeuronParams(), 7
    constants = kernel_constants(params)
    neurons = np.stack([np.full(n, constants[1]), np.full(n, constants[2])])
    if heterogeneous:
        neurons = neurons * rng.uniform(0.95, 1.05, (2, n))
    state = random_states(rng, 40, n, params)
    for weights in networks(rng, n):
        actions = rng.integers(-1, n, (40, 1))
        expected = state.copy()
        out_v, out_s = np.empty((40, 1, n)), np.empty((40, 1, n), dtype=bool)
        # Without heterogeneity the kernel runs its None path: the planner's arrays of
        # the model's constants must give the same numbers.
        advance(expected, weights[None], actions, params, out_v, out_s,
                neurons[None] if heterogeneous else None)  # fmt: skip
        for b in range(40):
            after, voltage, spikes, _ = one_step(weights, state, b, actions[b, 0], constants,
                                                 neurons)  # fmt: skip
            np.testing.assert_array_equal(after[0], expected.voltage_mV[b])
            np.testing.assert_array_equal(after[1], expected.refractory_left[b])
            np.testing.assert_array_equal(after[2], expected.steps_since_release[b])
            np.testing.assert_array_equal(after[3], expected.released[b])
            np.testing.assert_array_equal(voltage, out_v[b, 0])
            np.testing.assert_array_equal(spikes, out_s[b, 0])


@pytest.mark.parametrize("heterogeneous", [False, True])
def test_an_action_is_the_do_nothing_step_with_its_neuron_stepped_again(heterogeneous):
    rng = np.random.default_rng(2)
    params, n = NeuronParams(), 6
    constants = kernel_constants(params)
    model = step_constants(constants)
    neurons = np.stack([np.full(n, constants[1]), np.full(n, constants[2])])
    if heterogeneous:
        neurons = neurons * rng.uniform(0.95, 1.05, (2, n))
    state = random_states(rng, 30, n, params)
    for weights in networks(rng, n):
        for b in range(30):
            nothing, _, nothing_spikes, synaptic = one_step(
                weights, state, b, DO_NOTHING, constants, neurons
            )
            for a in range(n):
                expected, expected_v, expected_s, _ = one_step(weights, state, b, a, constants,
                                                               neurons)  # fmt: skip
                v_a, r_a, since_a, x_a, out_v_a, spiked_a = step_neuron(
                    a, state.voltage_mV[b, a], state.refractory_left[b, a],
                    state.steps_since_release[b, a], synaptic[a], a, model, neurons[0, a],
                    neurons[1, a], False, False, None,
                )  # fmt: skip
                for k, value in enumerate((v_a, r_a, since_a, x_a)):
                    derived = nothing[k].copy()
                    derived[a] = value
                    np.testing.assert_array_equal(derived, expected[k])
                assert out_v_a == expected_v[a] and spiked_a == expected_s[a]
                others = np.arange(n) != a
                np.testing.assert_array_equal(nothing_spikes[others], expected_s[others])


def test_predict_neuron_is_the_step_of_that_neuron():
    rng = np.random.default_rng(3)
    params, n = NeuronParams(), 8
    constants = kernel_constants(params)
    model = step_constants(constants)
    neurons = np.stack([np.full(n, constants[1]), np.full(n, constants[2])])
    state = random_states(rng, 50, n, params)
    for weights in networks(rng, n):
        for b in range(50):
            action = int(rng.integers(-1, n))
            _, voltage, spikes, _ = one_step(weights, state, b, action, constants, neurons)
            for j in range(n):
                predicted = predict_neuron(
                    weights, action, state.voltage_mV[b], state.refractory_left[b],
                    state.released[b], model, j, neurons[0], neurons[1],
                )  # fmt: skip
                assert predicted == (voltage[j], spikes[j])
                assert predict_neuron(
                    weights, action, state.voltage_mV[b], state.refractory_left[b],
                    state.released[b], model, j, None, None,
                ) == (voltage[j], spikes[j])  # fmt: skip
