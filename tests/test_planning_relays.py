"""Relays through hidden neurons (spikectl.planning.relays): the two-step effects the
estimate learns on hand-built evidence (posteriors computed here by hand), the virtual
relay neurons' state and weights, and identify-and-plan driving a target whose only
input is a hidden neuron, on a hand-built network simulated in full."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import play_by_hand, play_legally

from spikectl.contexts.generation import connection_probability
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.kernel import SINCE_RELEASE_CAP
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import SimulatorState
from spikectl.planning import (
    Composition,
    DecisionSettings,
    EstimatorSettings,
    IdentifyAndPlan,
    ObservationSettings,
    composition_name,
)
from spikectl.planning.identify import NOISE_FREE_SD
from spikectl.planning.relays import (
    RELAY_PRIOR_VARIANCE,
    RelayConnectivityEstimate,
    relay_state,
    relay_weights,
)

RELAYS = Composition("relays", EstimatorSettings("relays"))

PARAMS = NeuronParams()
EVERY = np.ones(3, dtype=bool)


def test_a_residual_two_steps_after_a_lone_release_is_a_relay():
    """Neuron 0 releases alone at step 0; at step 1 nothing moves, at step 2 neuron 2
    rises by one synaptic step with no release at step 1: L[0, 2] takes it (posterior
    mean v / (v + s^2) of one observation with prior variance v, noise s), and G[0, 2]
    is 0 and known (step 1 showed no direct effect)."""
    estimate = RelayConnectivityEstimate(3, NOISE_FREE_SD)
    estimate.add(np.array([1.0, 0, 0]), np.zeros(3), EVERY)  # step 1: released(0) = {0}
    estimate.add(np.zeros(3), np.array([0.0, 0, 1]), EVERY)  # step 2: released(1) = {}
    variance, noise = RELAY_PRIOR_VARIANCE, NOISE_FREE_SD**2
    mean, sd = estimate.relays()
    assert mean[0, 2] == pytest.approx(variance / (variance + noise))
    assert sd[0, 2] == pytest.approx(np.sqrt(variance * noise / (variance + noise)))
    assert np.abs(np.delete(mean.ravel(), 2)).max() < 1e-12  # no other relay
    g_mean, g_sd = estimate.posterior()
    assert abs(g_mean[0, 2]) < 1e-12 and g_sd[0, 2] < 0.25
    assert estimate.relay_signs(0.25)[0, 2] == 1
    assert estimate.weights(0.25)[0][0, 2] == 0


def test_a_release_that_follows_another_keeps_the_credit_by_the_priors():
    """Neuron 0 releases at step 0 and neuron 1 at step 1 (as a cascade would); neuron 2
    rises at step 2. The direct synapse 1 -> 2 (prior variance p) and the relay 0 -> 2
    (variance v) explain it equally: they share it as p : v, their sum is known."""
    estimate = RelayConnectivityEstimate(3, NOISE_FREE_SD)
    estimate.add(np.array([1.0, 0, 0]), np.zeros(3), EVERY)
    estimate.add(np.array([0.0, 1, 0]), np.array([0.0, 0, 1]), EVERY)
    p, v, noise = connection_probability(np.array([1]))[0], RELAY_PRIOR_VARIANCE, NOISE_FREE_SD**2
    direct, relay = estimate.posterior()[0][1, 2], estimate.relays()[0][0, 2]
    assert direct == pytest.approx(p / (p + v + noise))
    assert relay == pytest.approx(v / (p + v + noise))
    assert estimate.weights(0.25)[0][1, 2] == 1 and estimate.relay_signs(0.25)[0, 2] == 0


def test_relay_state_and_weights():
    """v_i fired at the last step where i released the step before; its vesicles went
    one step after i's; i releasing now or never leaves v_i with no release on record."""
    state = SimulatorState.at_rest(1, 5, PARAMS)
    state.steps_since_release[0] = [0, 1, 2, 5, SINCE_RELEASE_CAP]
    state.released[0] = [True, False, False, False, False]
    state.refractory_left[0] = [1, 0, 0, 0, 0]
    planned = relay_state(state, PARAMS)
    assert planned.voltage_mV.shape == (1, 10)
    assert (planned.steps_since_release[0, :5] == state.steps_since_release[0]).all()
    assert (planned.released[0, :5] == state.released[0]).all()
    cap = SINCE_RELEASE_CAP
    assert planned.steps_since_release[0, 5:].tolist() == [cap, 0, 1, 4, cap]
    assert planned.released[0, 5:].tolist() == [False, True, False, False, False]
    assert planned.refractory_left[0, 5:].tolist() == [0, 1, 0, 0, 0]
    assert (planned.voltage_mV[0, 5:] == PARAMS.v_rest_mV).all()
    weights = np.array([[0, 1], [-1, 0]], dtype=np.int8)
    relays = np.array([[0, 0], [0, 1]], dtype=np.int8)
    assert relay_weights(weights, relays).tolist() == [
        [0, 1, 1, 0], [-1, 0, 0, 1], [0, 0, 0, 0], [0, 1, 0, 0]]  # fmt: skip


@pytest.mark.parametrize("relays", [True, False])
def test_a_target_driven_only_through_a_hidden_neuron(relays):
    """Observed 0, 1, 2 (the target), hidden 3; the only path to the target is
    0 -> 3 -> 2. A probe of 0 at step 0 (and nothing at step 1, so that no other
    release explains it) fires the target at step 2 (wanted); a spike is wanted again
    at step 12. With relays the policy learned the relay at step 2 and
    stimulates 0 at step 10, and the target fires at 12; without, the two-step effect
    is invisible to it and step 12 is missed."""
    weights = np.zeros((4, 4), dtype=np.int8)
    weights[0, 3] = weights[3, 2] = 1
    pattern = np.zeros(20, dtype=bool)
    pattern[[2, 12]] = True
    policy = IdentifyAndPlan(composition=RELAYS if relays else None)
    actions, fired = play_by_hand(policy, weights, 2, pattern, [0, -1], observed=[0, 1, 2])
    fired = np.array(fired)
    assert fired[2]
    assert (actions[10] == 0) == relays
    assert fired[12] == relays
    assert (fired == pattern).all() == relays


def test_the_named_controller_plans_relays_with_hidden_neurons_alone():
    assert composition_name(Extensions(hidden_fraction=0.25), 8) == "hidden"
    assert composition_name(Extensions(hidden_neurons=1), 8) == "hidden"
    noisy = Extensions(hidden_fraction=0.25, observation_noise_mV=1.0)
    assert composition_name(noisy, 8) == "noise"
    assert composition_name(None, 8) == "paper"


def test_the_relay_estimate_refuses_a_bad_prior():
    with pytest.raises(ValueError, match="relay_variance must be > 0"):
        RelayConnectivityEstimate(3, NOISE_FREE_SD, relay_variance=0.0)


@pytest.mark.parametrize(
    ("extensions", "observation"),
    [(None, ObservationSettings()),
     ({"hidden_fraction": 0.25, "threshold_spread": 0.1, "time_constant_spread": 0.1},
      ObservationSettings(task_model=True)),
     ({"hidden_fraction": 0.25, "observation_noise_mV": 2.0},
      ObservationSettings(filter_voltage=True))],
    ids=["observed state", "neuron tracker", "filtered state"],
)  # fmt: skip
def test_relays_play_legally_with_every_tracker(extensions, observation):
    """Relays on hidden-neuron environments beside each tracker the policy can have (the
    virtual relay neurons get the paper's parameters beside the tracked ones)."""
    env = gym.make("spikectl/NeuronControlPartial-v0", contexts={"n_train": 4, "n_test": 4},
                   **({} if extensions is None else {"extensions": extensions}))  # fmt: skip
    composition = RELAYS.but("relays-width8", observation=observation,
                             decision=DecisionSettings(width=8))  # fmt: skip
    policy = IdentifyAndPlan(composition=composition, extensions=env.unwrapped.extensions)
    play_legally(env, policy, range(3))
    assert policy.estimate.relays()[0].shape == (6, 6)
