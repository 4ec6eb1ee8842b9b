"""Hand-computed dynamics of the model (docs/model.md), batching and input validation."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from spikectl import NeuronParams, simulate
from spikectl.contexts.generation import generate_topology
from spikectl.neuron.kernel import CONSTANTS, kernel_constants
from spikectl.neuron.prediction import one_step
from spikectl.neuron.simulator import (
    PARALLEL_MIN_BATCH,
    PARALLEL_MIN_WORK,
    DrawnInputs,
    SimulatorState,
    advance,
    as_weight_batch,
    neuron_parameters,
)

V_REST = -70.0
NOTHING = -1


def chain(n: int = 2, sign: int = 1) -> np.ndarray:
    """0 -> 1 -> ... -> n-1, every edge with the given sign."""
    weights = np.zeros((n, n), dtype=np.int8)
    for i in range(n - 1):
        weights[i, i + 1] = sign
    return weights


def test_stimulated_neuron_at_rest_spikes_at_plus_40_mV():
    voltages, spikes = simulate(np.zeros((3, 3)), [1])
    assert voltages[0].tolist() == [V_REST, V_REST + 40.0, V_REST]
    assert spikes[0].tolist() == [False, True, False]


def test_one_excitatory_input_from_rest_reaches_exactly_threshold_and_fires():
    voltages, spikes = simulate(chain(), [0, NOTHING, NOTHING])
    assert voltages[1, 1] == -50.0  # exact, not approximately
    assert spikes[:, 1].tolist() == [False, True, False]
    # The one-step synaptic delay: nothing reaches neuron 1 during step 0.
    assert voltages[0, 1] == V_REST


def test_inhibition_gives_minus_20_mV_and_decays_with_tau_20_ms():
    steps = 30
    voltages, spikes = simulate(chain(sign=-1), [0] + [NOTHING] * (steps - 1))
    assert voltages[1, 1] == V_REST - 20.0
    # Euler with dt = 1 ms and RC = 20 ms: the deviation from rest shrinks by 1 - 1/20.
    deviation = voltages[1:, 1] - V_REST
    expected = -20.0 * 0.95 ** np.arange(steps - 1)
    np.testing.assert_allclose(deviation, expected, rtol=1e-12)
    assert not spikes[:, 1].any()


def test_inputs_add_within_a_step():
    # Neuron 3 drives 0 and 1, which both spike at step 1; their inputs meet in 2 at step 2.
    weights = np.zeros((4, 4), dtype=np.int8)
    weights[3, 0] = weights[3, 1] = 1
    weights[0, 2] = 1
    for sign_of_1, expected_mV in [(1, -30.0), (-1, V_REST)]:
        weights[1, 2] = sign_of_1
        voltages, spikes = simulate(weights, [3, NOTHING, NOTHING])
        assert spikes[1, 0] and spikes[1, 1]
        assert voltages[2, 2] == expected_mV


def test_refractory_neuron_cannot_spike_on_consecutive_steps_even_when_stimulated():
    voltages, spikes = simulate(np.zeros((2, 2)), [0, 0, 0, 0])
    assert spikes[:, 0].tolist() == [True, False, True, False]
    assert voltages[1, 0] == V_REST  # held at rest, the stimulus discarded


def test_refractory_neuron_discards_synaptic_input():
    # 2 -> 1 and 0 -> 1. Stimulating 2 then 0 makes 1 spike at step 1 (from 2), so 0's
    # input reaches 1 at step 2 while it is refractory: it is discarded, not deferred.
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[2, 1] = weights[0, 1] = 1
    voltages, spikes = simulate(weights, [2, 0, NOTHING, NOTHING])
    assert spikes[1, 1]
    assert voltages[2, 1] == V_REST and not spikes[2, 1]
    assert voltages[3, 1] == V_REST
    # Without the earlier spike the same input fires neuron 1.
    _, spikes = simulate(weights, [NOTHING, 0, NOTHING, NOTHING])
    assert spikes[2, 1]


def test_synapse_releases_at_most_every_5_steps():
    # Stimulating neuron 0 at every step makes it spike every other step (refractory).
    voltages, spikes = simulate(chain(), [0] * 20)
    assert np.flatnonzero(spikes[:, 0]).tolist() == list(range(0, 20, 2))
    # It releases at steps 0, 6, 12, 18 (>= 5 steps apart), so neuron 1 fires one step later.
    assert np.flatnonzero(spikes[:, 1]).tolist() == [1, 7, 13, 19]


def test_release_interval_boundary_is_exactly_5_steps():
    actions = np.full(10, NOTHING)
    actions[[0, 5]] = 0  # 5 steps apart: both release
    _, spikes = simulate(chain(), actions)
    assert np.flatnonzero(spikes[:, 1]).tolist() == [1, 6]
    actions = np.full(10, NOTHING)
    actions[[0, 4]] = 0  # 4 steps apart: the second spike releases nothing
    _, spikes = simulate(chain(), actions)
    assert np.flatnonzero(spikes[:, 1]).tolist() == [1]


def test_spike_without_release_still_counts_as_a_spike():
    actions = np.full(6, NOTHING)
    actions[[0, 2]] = 0
    _, spikes = simulate(chain(), actions)
    assert spikes[2, 0]  # a spike of neuron 0 ...
    assert not spikes[3, 1]  # ... whose synapse had not recovered


def test_no_activity_without_input():
    rng = np.random.default_rng(1)
    weights = np.stack([generate_topology(8, rng) for _ in range(50)])
    voltages, spikes = simulate(weights, np.full((50, 60), NOTHING))
    assert (voltages == V_REST).all()
    assert not spikes.any()


def test_threshold_is_inclusive_with_tolerance_so_round_off_never_decides():
    # Input that lands 0.5e-6 mV below threshold still fires; 3e-6 mV below does not.
    just_below = NeuronParams(synaptic_current_pA=600.0 - 0.5e-6 * 30.0)
    _, spikes = simulate(chain(), [0, NOTHING], just_below)
    assert spikes[1, 1]
    clearly_below = NeuronParams(synaptic_current_pA=600.0 - 3e-6 * 30.0)
    _, spikes = simulate(chain(), [0, NOTHING], clearly_below)
    assert not spikes[1, 1]


def test_low_release_scale_never_releases():
    params = NeuronParams(release_scale=0.4)
    _, spikes = simulate(chain(), [0] * 30, params)
    assert spikes[:, 0].any() and not spikes[:, 1].any()


def test_longer_refractory_period():
    _, spikes = simulate(np.zeros((2, 2)), [0] * 9, NeuronParams(refractory_steps=2))
    assert np.flatnonzero(spikes[:, 0]).tolist() == [0, 3, 6]


def random_batch(batch: int, n: int, steps: int, seed: int):
    rng = np.random.default_rng(seed)
    weights = np.stack([generate_topology(n, rng) for _ in range(batch)])
    actions = rng.integers(NOTHING, n, size=(batch, steps))
    return weights, actions


def test_batched_equals_one_network_at_a_time():
    weights, actions = random_batch(20, 8, 60, seed=2)
    voltages, spikes = simulate(weights, actions)
    for b in range(20):
        v_b, s_b = simulate(weights[b], actions[b])
        np.testing.assert_array_equal(voltages[b], v_b)
        np.testing.assert_array_equal(spikes[b], s_b)


def test_threaded_kernel_equals_serial_kernel():
    batch = max(PARALLEL_MIN_BATCH, PARALLEL_MIN_WORK // (60 * 8)) + 44
    assert batch // 2 * 60 * 8 < PARALLEL_MIN_WORK or batch // 2 < PARALLEL_MIN_BATCH
    weights, actions = random_batch(batch, 8, 60, seed=3)
    voltages, spikes = simulate(weights, actions)  # threaded
    half = batch // 2  # too little work per call: serial
    v_serial = np.concatenate(
        [simulate(weights[:half], actions[:half])[0], simulate(weights[half:], actions[half:])[0]]
    )
    np.testing.assert_array_equal(voltages, v_serial)
    assert spikes.any()


def test_shared_weights_broadcast_over_the_batch():
    weights, actions = random_batch(1, 8, 40, seed=4)
    actions = np.random.default_rng(5).integers(NOTHING, 8, size=(6, 40))
    voltages, _ = simulate(weights[0], actions)
    for b in range(6):
        np.testing.assert_array_equal(voltages[b], simulate(weights[0], actions[b])[0])


def test_stepwise_advance_equals_whole_sequence():
    weights, actions = random_batch(5, 8, 30, seed=6)
    voltages, spikes = simulate(weights, actions)
    params = NeuronParams()
    state = SimulatorState.at_rest(5, 8, params)
    weight_batch = as_weight_batch(weights)
    out_v = np.empty((5, 1, 8))
    out_s = np.empty((5, 1, 8), dtype=bool)
    for t in range(30):
        advance(
            state, weight_batch, np.ascontiguousarray(actions[:, t : t + 1]), params, out_v, out_s
        )
        np.testing.assert_array_equal(out_v[:, 0], voltages[:, t])
        np.testing.assert_array_equal(out_s[:, 0], spikes[:, t])


def test_deterministic():
    weights, actions = random_batch(8, 8, 60, seed=7)
    first = simulate(weights, actions)
    second = simulate(weights, actions)
    np.testing.assert_array_equal(first[0], second[0])


def test_pure_python_path_matches_jit():
    """NUMBA_DISABLE_JIT runs the same kernel as plain Python: one implementation."""
    weights, actions = random_batch(3, 6, 25, seed=8)
    voltages, spikes = simulate(weights, actions)
    code = (
        "import json, sys, numpy as np; from spikectl import simulate; "
        "d = json.load(sys.stdin); v, s = simulate(np.array(d['w']), np.array(d['a'])); "
        "print(json.dumps([v.tolist(), s.tolist()]))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        input=json.dumps({"w": weights.tolist(), "a": actions.tolist()}),
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
    )
    v_python, s_python = json.loads(result.stdout)
    np.testing.assert_array_equal(voltages, np.array(v_python))
    np.testing.assert_array_equal(spikes, np.array(s_python))


def test_kernel_constants_are_the_named_params_quantities():
    params = NeuronParams(refractory_steps=3, release_scale=0.9)
    constants = kernel_constants(params)
    assert constants.tolist() == [float(getattr(params, name)) for name in CONSTANTS]
    assert constants[CONSTANTS.index("synaptic_step_mV")] == 20.0


def test_one_step_prediction_by_hand():
    # 0 -> 2 excitatory, 1 -> 2 inhibitory, 0 and 1 released at the last step; 2 at
    # -60 mV: -60 + (10 * 0.05 -> -0.5 leak) + 20 - 20 = -60.5; neuron 1 refractory.
    params = NeuronParams()
    state = SimulatorState.at_rest(2, 3, params)
    state.voltage_mV[:] = [-70.0, -70.0, -60.0]
    state.released[:] = [True, True, False]
    state.refractory_left[:, 1] = 1
    weights = np.zeros((1, 3, 3), dtype=np.int8)
    weights[0, 0, 2], weights[0, 1, 2] = 1, -1
    voltage, spiked = one_step(state, weights, np.array([NOTHING, 0]), params)
    assert voltage.tolist() == [[-70.0, -70.0, -60.5], [-30.0, -70.0, -60.5]]
    assert spiked.tolist() == [[False, False, False], [True, False, False]]
    target_voltage, target_spiked = one_step(state, weights, NOTHING, params, neuron=2)
    assert target_voltage.tolist() == [-60.5, -60.5] and not target_spiked.any()
    assert state.voltage_mV[0].tolist() == [-70.0, -70.0, -60.0]  # not advanced


@pytest.mark.parametrize("variant", ["paper", "scaled", "heterogeneous", "input"])
def test_one_step_prediction_equals_the_simulator_step_exactly(variant):
    batch, n, steps = 64, 8, 40
    rng = np.random.default_rng(11)
    weights, actions = random_batch(batch, n, steps, seed=12)
    weights = as_weight_batch(weights)
    params = NeuronParams(refractory_steps=2) if variant == "paper" else NeuronParams()
    neurons = input_mV = None
    if variant == "scaled":
        weights = np.ascontiguousarray(weights * rng.uniform(0.3, 1.7, (batch, n, n)))
    if variant == "heterogeneous":
        neurons = neuron_parameters(
            params, -50.0 + rng.uniform(-3, 3, (batch, n)), rng.uniform(10, 30, (batch, n))
        )
    if variant == "input":
        input_mV = rng.normal(0.0, 8.0, (batch, steps, n))
    state = SimulatorState.at_rest(batch, n, params)
    out_v = np.empty((batch, 1, n))
    out_s = np.empty((batch, 1, n), dtype=bool)
    for t in range(steps):
        step_input = None if input_mV is None else np.ascontiguousarray(input_mV[:, t : t + 1])
        one_input = None if step_input is None else step_input[:, 0]
        predicted_v, predicted_s = one_step(
            state, weights, actions[:, t], params, neurons, one_input
        )
        target_v, target_s = one_step(
            state, weights, actions[:, t], params, neurons, one_input, neuron=t % n
        )
        step_actions = np.ascontiguousarray(actions[:, t : t + 1])
        advance(state, weights, step_actions, params, out_v, out_s, neurons,
                DrawnInputs(None, step_input))  # fmt: skip
        np.testing.assert_array_equal(predicted_v, out_v[:, 0])
        np.testing.assert_array_equal(predicted_s, out_s[:, 0])
        np.testing.assert_array_equal(target_v, out_v[:, 0, t % n])
        np.testing.assert_array_equal(target_s, out_s[:, 0, t % n])
    assert out_s.any() or state.released.any()


@pytest.mark.parametrize(
    ("weights", "actions", "error", "message"),
    [
        (np.zeros((2, 3)), [0], ValueError, "shape"),
        (np.zeros((2, 2, 2, 2)), [0], ValueError, "shape"),
        (np.full((2, 2), 2) * (1 - np.eye(2)), [0], ValueError, "-1"),
        (np.eye(2), [0], ValueError, "diagonal"),
        (np.array([["a", "b"], ["c", "d"]]), [0], TypeError, "numeric"),
        (np.zeros((2, 2)), [2], ValueError, "-1..1"),
        (np.zeros((2, 2)), [-2], ValueError, "-1..1"),
        (np.zeros((2, 2)), [0.5], TypeError, "integers"),
        (np.zeros((2, 2)), np.zeros((2, 2, 2), dtype=int), ValueError, "actions must"),
        (np.zeros((3, 2, 2)), np.zeros((2, 5), dtype=int), ValueError, "batch"),
    ],
)
def test_bad_inputs_raise_clear_errors(weights, actions, error, message):
    with pytest.raises(error, match=message):
        simulate(weights, actions)


def test_bad_params_type():
    with pytest.raises(TypeError, match="NeuronParams"):
        simulate(np.zeros((2, 2)), [0], params={"v_rest_mV": -70})
