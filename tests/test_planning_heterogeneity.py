"""Each neuron's threshold and leak learned from what it does (spikectl.planning.
heterogeneity): values on a hand-built two-neuron network, then the reads, intervals and
leaks against the truth of heterogeneous networks played by identify-and-plan."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.contexts import make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, simulate
from spikectl.planning import Composition, IdentifyAndPlan, ObservationSettings
from spikectl.planning.heterogeneity import NeuronTracker, tracks_neurons

PARAMS = NeuronParams()
SPREADS = Extensions(threshold_spread=0.1, time_constant_spread=0.1, synaptic_spread=0.1)
TASK_MODEL = Composition("task-model", observation=ObservationSettings(task_model=True))


def test_a_single_release_settles_the_threshold_and_the_state():
    """Neuron 0 (stimulated at step 0) releases onto neuron 1 with strength 1.04: it lands
    at -70 + 20.8 = -49.2 mV, inside the prior's (-52, -48]. With threshold -49.5 mV it
    spikes; read provisionally as a spike (past the middle -50), settled by the V_r it
    shows next, and the interval's top drops to -49.2. With threshold -49.0 it does not:
    the same provisional read is undone (potential, refractoriness, release) and the
    interval's bottom rises to -49.2."""
    weights, scale = np.array([[0, 1], [0, 0]]), np.array([[1.0, 1.04], [1.0, 1.0]])
    actions = np.array([0, DO_NOTHING, DO_NOTHING])
    for threshold, spikes in ((-49.5, True), (-49.0, False)):
        voltage, truth = simulate(weights, actions, PARAMS, synaptic_scale=scale,
                                  thresholds_mV=np.array([-50.0, threshold]))  # fmt: skip
        assert bool(truth[1, 1]) == spikes and voltage[1, 1] == pytest.approx(-49.2)
        tracker = NeuronTracker(2, PARAMS, SPREADS)
        tracker.observe(voltage[0].astype(np.float32), 0)
        tracker.observe(voltage[1].astype(np.float32), DO_NOTHING)
        assert tracker.spiked[1] and tracker.state.released[0, 1]  # provisional: a spike
        seen = float(np.float32(voltage[1, 1]))
        tracker.observe(voltage[2].astype(np.float32), DO_NOTHING)
        if spikes:
            assert tracker.high[1] == seen and tracker.low[1] < -51.9
            assert tracker.state.refractory_left[0, 1] == 0  # its refractory step is over
        else:
            assert tracker.low[1] == seen and tracker.high[1] == pytest.approx(-48.0, abs=1e-5)
            # Undone: it kept its potential and did not release, so at step 2 it decayed.
            assert not tracker.spiked[1]
            assert tracker.state.voltage_mV[0, 1] == pytest.approx(
                seen - (seen - PARAMS.v_rest_mV) * PARAMS.leak_per_step, abs=1e-4
            )


def test_the_leak_is_measured_on_an_undriven_step():
    """Neuron 1 lifted to -52 mV by a weak synapse decays undriven: its measured leak is
    dt / tau_1 of its own time constant (12 ms here, the paper's 20)."""
    weights, scale = np.array([[0, 1], [0, 0]]), np.array([[1.0, 0.9], [1.0, 1.0]])
    actions = np.array([0, DO_NOTHING, DO_NOTHING, DO_NOTHING])
    taus = np.array([PARAMS.membrane_time_constant_ms, 12.0])
    voltage, _ = simulate(weights, actions, PARAMS, membrane_time_constants_ms=taus,
                          synaptic_scale=scale)  # fmt: skip
    tracker = NeuronTracker(2, PARAMS, SPREADS)
    for step, action in enumerate(actions):
        tracker.observe(voltage[step].astype(np.float32), int(action))
    assert tracker.leak[1] == pytest.approx(PARAMS.dt_ms / 12.0, rel=1e-4)
    assert tracker.leak[0] == PARAMS.leak_per_step  # never off rest undriven: the paper's


def test_played_on_heterogeneous_networks_the_reads_intervals_and_leaks_are_true():
    """Identify-and-plan told the extensions, on heterogeneous networks: every settled
    read is the network's spike, every threshold lies in its interval, every measured
    leak is the neuron's own, every known synapse is planned at its strength."""
    contexts, _ = make_splits(6, 1, 8, 60, seed=3, extensions=SPREADS)
    env = NeuronControlEnv(contexts=contexts, extensions=SPREADS)
    narrowed = 0
    for index in range(len(contexts)):
        policy = IdentifyAndPlan(PARAMS, TASK_MODEL, extensions=SPREADS)
        observation, info = env.reset(seed=0, options={"context": index})
        truth, settled = [], []
        action = policy.act(observation, info)
        tracker = policy.reader.tracker
        assert isinstance(tracker, NeuronTracker)
        settle = tracker._settle

        def recording(seen, settle=settle, tracker=tracker, settled=settled):
            settle(seen)
            settled.append(tracker.spiked.copy())

        tracker._settle = recording
        while True:
            observation, _, done, _, info = env.step(action)
            truth.append(info["spikes"])
            if done:
                break
            action = policy.act(observation, info)
        # settled[k] is the read of step k, settled when step k + 1 was observed.
        np.testing.assert_array_equal(np.array(settled[1:]), np.array(truth[: len(settled) - 1]))
        heterogeneity = contexts[index].heterogeneity
        theta = heterogeneity.thresholds_mV - PARAMS.threshold_tolerance_mV
        assert np.all(tracker.low < theta) and np.all(theta <= tracker.high)
        narrowed += int(np.sum(tracker.high - tracker.low < 3.99))
        # Known synapses are planned at their strength (the synaptic spread), not their sign.
        planned, known = policy.planning_weights()
        strengths = contexts[index].weights * heterogeneity.synaptic_scale
        np.testing.assert_allclose(planned[known], strengths[known], atol=0.02)
        own = PARAMS.dt_ms / heterogeneity.time_constants_ms
        measured = tracker.leak != PARAMS.leak_per_step
        np.testing.assert_allclose(tracker.leak[measured], own[measured], rtol=1e-3)
    assert narrowed > 0  # the test saw intervals narrow


def test_which_environments_track_neurons():
    assert tracks_neurons(SPREADS, 0.0, PARAMS)
    assert tracks_neurons(Extensions(time_constant_spread=0.1), 0.0, PARAMS)
    assert not tracks_neurons(Extensions(synaptic_spread=0.1), 0.0, PARAMS)  # neurons alike
    assert not tracks_neurons(None, 0.0, PARAMS) and not tracks_neurons(Extensions(), 0.0, PARAMS)
    assert not tracks_neurons(SPREADS, 1.0, PARAMS)  # a settled read needs V_r seen exactly
    noisy = Extensions(threshold_spread=0.1, observation_noise_mV=1.0)
    assert not tracks_neurons(noisy, 0.0, PARAMS)
    no_refractory = NeuronParams(refractory_steps=0)
    assert not tracks_neurons(SPREADS, 0.0, no_refractory)  # nothing settles a read
    with pytest.raises(ValueError, match="refractory_steps must be >= 1"):
        NeuronTracker(2, no_refractory, SPREADS)
    # The policy then keeps the paper's tracker and still plays.
    contexts, _ = make_splits(1, 1, 8, 60, seed=3, params=no_refractory, extensions=SPREADS)
    env = NeuronControlEnv(contexts=contexts, extensions=SPREADS)
    policy = IdentifyAndPlan(no_refractory, TASK_MODEL, extensions=SPREADS)
    observation, info = env.reset(seed=0, options={"context": 0})
    env.step(policy.act(observation, info))
    assert type(policy.reader.tracker).__name__ == "ObservedState"


def test_the_paper_and_its_planner_are_unchanged_by_the_tracker():
    """Without heterogeneous neurons the policy keeps the paper's tracker and plans on
    signs: the same actions as before on the paper's networks."""
    from spikectl.planning.identify import ObservedState

    contexts, _ = make_splits(3, 1, 8, 60, seed=4)
    env = NeuronControlEnv(contexts=contexts)
    for index in range(len(contexts)):
        plain = IdentifyAndPlan(PARAMS)
        told = IdentifyAndPlan(PARAMS, TASK_MODEL, extensions=Extensions())
        observation, info = env.reset(seed=0, options={"context": index})
        done = False
        while not done:
            action = plain.act(observation, info)
            assert told.act(observation, info) == action
            observation, _, done, _, info = env.step(action)
        assert type(told.reader.tracker) is ObservedState
