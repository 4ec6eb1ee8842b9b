"""The spike likelihood (spikectl.planning.spike_likelihood): spikes read under background
input and the ChR2 light, and the ``rig`` composition that plays it."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.contexts import Context, ContextSet
from spikectl.contexts.generation import generate_topology
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, simulate
from spikectl.planning import (
    Composition,
    EstimatorSettings,
    IdentifyAndPlan,
    ObservationSettings,
    named_composition,
)
from spikectl.planning.named import composition_name
from spikectl.planning.spike_filter import SpikeFilter, SpikesInconsistent, SpikeState
from spikectl.planning.spike_likelihood import SpikeLikelihoodFilter, SpikeLikelihoodState

PARAMS = NeuronParams()
RIG = Extensions(actuator="chr2", latency_steps=2, sensing="spikes", background_rate=0.005)


def true_columns(estimate, weights: np.ndarray) -> list[int]:
    """Each neuron's index of its true input column among the filter's hypotheses."""
    n = weights.shape[0]
    return [int(np.flatnonzero((estimate.hypotheses[j] == weights[:, j]).all(axis=1))[0])
            for j in range(n)]  # fmt: skip


@pytest.mark.parametrize("seed", range(3))
def test_without_background_or_light_it_is_the_exact_filter(seed):
    """Background rate 0, the current pulse: the same surviving columns, posterior and
    potentials as the exact filter at every step."""
    rng = np.random.default_rng(seed)
    n, steps = 6, 50
    weights = generate_topology(n, rng)
    actions = np.where(rng.random(steps) < 0.6, rng.integers(0, n, steps), DO_NOTHING)
    spikes = simulate(weights, actions[None], PARAMS)[1][0]
    exact, exact_state = SpikeFilter(n, PARAMS), SpikeState(n, PARAMS, 0.0)
    mine, my_state = SpikeLikelihoodFilter(n, PARAMS, 0.0), SpikeLikelihoodState(n, PARAMS, 0.0)
    for t in range(steps):
        exact.add(*exact_state.observe(spikes[t].astype(np.int8), int(actions[t])))
        exact_state.follow(exact)
        evidence = my_state.observe(spikes[t].astype(np.int8), int(actions[t]))
        assert evidence[-1] is None  # no opsin
        mine.add(*evidence)
        my_state.follow(mine)
        np.testing.assert_array_equal(mine.alive, exact.alive)
        np.testing.assert_array_equal(mine.log_weights, exact.log_weights)
        np.testing.assert_array_equal(mine.potentials, exact.potentials)
    assert exact.alive.sum() < exact.alive.size  # the spikes taught something
    with pytest.raises(SpikesInconsistent, match="impossible under every input column"):
        fresh, state = SpikeLikelihoodFilter(3, PARAMS, 0.0), SpikeLikelihoodState(3, PARAMS, 0.0)
        fresh.add(*state.observe(np.array([0, 1, 0], dtype=np.int8), DO_NOTHING))


def test_an_unexplained_spike_costs_the_background_chance():
    """One spike from rest with no input: every column predicts silence, so each pays the
    same cost and the posterior stays the prior (no column is dropped); a silent step where
    a column predicts a spike costs that column the miss probability."""
    estimate, state = SpikeLikelihoodFilter(3, PARAMS, 0.01), SpikeLikelihoodState(3, PARAMS, 0.0)
    prior = estimate.log_weights.copy()
    estimate.add(*state.observe(np.array([0, 1, 0], dtype=np.int8), DO_NOTHING))
    state.follow(estimate)
    assert estimate.alive.all()
    np.testing.assert_array_equal(estimate.log_weights, prior)
    # Neuron 1 spiked and released: next step the columns with 1 -> 0 excitatory predict
    # neuron 0 at -70 + 20 = -50 mV, a spike; it stays silent.
    estimate.add(*state.observe(np.array([0, 0, 0], dtype=np.int8), DO_NOTHING))
    excited = estimate.hypotheses[0][:, 1] == 1
    silent = np.log1p(np.expm1(-0.01))  # no spontaneous input in the step
    np.testing.assert_allclose(estimate.log_likelihood[0][excited], np.log(1e-3) - silent)
    assert (estimate.log_likelihood[0][~excited] == 0).all()
    assert estimate.column_weights()[0][excited].sum() < np.exp(prior[0][excited]).sum() / 100


def drive_episode(extensions: Extensions, weights: np.ndarray, seed: int, steps: int = 60):
    """Run the environment on ``weights`` under random light or pulses, reading each step
    into a fresh spike likelihood through the observation part (as identify-and-plan
    does); yields (filter, the environment's true potentials after reset) each step."""
    n = weights.shape[0]
    rng = np.random.default_rng(seed)
    pattern = np.zeros(steps, dtype=bool)
    pattern[steps // 2] = True  # the reward needs one wanted spike; the test reads no reward
    contexts = ContextSet([Context(weights, n - 1, pattern)], PARAMS)
    env = NeuronControlEnv(contexts=contexts, extensions=extensions)
    observation = ObservationSettings(task_model=True).bind(PARAMS, extensions)
    reader = observation.reader(n, 0)
    estimate = SpikeLikelihoodFilter(n, PARAMS, extensions.background_rate)
    obs, info = env.reset(seed=seed, options={"context": 0})
    for _ in range(steps - 1):
        action = int(rng.integers(0, n - 1)) if rng.random() < 0.3 else DO_NOTHING
        obs, _, terminated, truncated, info = env.step(action)
        estimate.add(*reader.read(obs["spikes"], action, estimate))
        reader.settle(estimate)
        yield estimate, env.unwrapped._state.voltage_mV[0].copy()
        if terminated or truncated:
            return


@pytest.mark.parametrize("seed", range(3))
def test_the_light_enters_each_potential_as_the_environment_computes_it(seed):
    """ChR2 light, spikes only, no background: the true column's potential is the
    simulator's bit for bit at every step, and it keeps all the likelihood."""
    extensions = Extensions(actuator="chr2", sensing="spikes")
    weights = generate_topology(5, np.random.default_rng(seed))
    truth = None
    for estimate, voltage in drive_episode(extensions, weights, seed):
        truth = true_columns(estimate, weights) if truth is None else truth
        for j in range(5):
            assert estimate.potentials[j, truth[j]] == voltage[j]
            assert estimate.log_likelihood[j, truth[j]] == 0.0
    assert truth is not None


@pytest.mark.parametrize("seed", range(4))
def test_under_background_input_the_true_column_keeps_weight(seed):
    """Background input at 20 times the rig's rate and the light: spikes no column
    predicts happen, and the true column of every neuron is never given zero weight."""
    extensions = Extensions(actuator="chr2", sensing="spikes", background_rate=0.1)
    weights = generate_topology(5, np.random.default_rng(seed))
    truth = None
    for estimate, _ in drive_episode(extensions, weights, seed):
        truth = true_columns(estimate, weights) if truth is None else truth
        weights_now = estimate.column_weights()
        for j in range(5):
            assert estimate.alive[j, truth[j]] and weights_now[j, truth[j]] > 0
    assert truth is not None and estimate.alive.sum() < estimate.alive.size


def test_the_rig_composition_is_chosen_and_refuses_what_it_cannot_read():
    assert composition_name(RIG, 8) == "rig"
    assert composition_name(Extensions(sensing="spikes", background_rate=0.005)) == "rig"
    assert composition_name(Extensions(sensing="spikes")) == "spikes"
    assert composition_name(Extensions(actuator="chr2")) == "chr2"
    assert composition_name(Extensions(background_rate=0.005)) == "background"
    rig = named_composition(RIG, 8)
    assert rig.estimator.kind == "spike-likelihood" and rig.observation.task_model
    for field, value in (("hidden_neurons", 2), ("stochastic_release", True),
                         ("threshold_spread", 0.1), ("recorded_neurons", 4)):  # fmt: skip
        extensions = Extensions(**{**RIG.__dict__, field: value})
        with pytest.raises(ValueError, match=f"under background input and the ChR2 light; "
                                             f"it cannot with {field}$"):  # fmt: skip
            IdentifyAndPlan(composition=named_composition(extensions, 8), extensions=extensions)
    # The exact filter still refuses the rig in one line; each estimator with its model.
    with pytest.raises(ValueError, match="it cannot with background_rate, actuator='chr2'"):
        IdentifyAndPlan(composition=named_composition(Extensions(sensing="spikes")),
                        extensions=RIG)  # fmt: skip
    with pytest.raises(ValueError, match="'mine' keeps 'spike-likelihood' with task_model=False"):
        IdentifyAndPlan(composition=Composition("mine", EstimatorSettings("spike-likelihood")),
                        extensions=Extensions(sensing="spikes"))  # fmt: skip


def test_identify_and_plan_plays_a_short_rig_episode_legally():
    """The named controller on the rig: legal actions, a return in [0, 1], the same
    episodes twice."""
    test_set = ContextSet.generate(2, n_neurons=8, seed=3)
    plays = [
        evaluate_policy(test_set, IdentifyAndPlan(test_set.params, named_composition(RIG, 8),
                                                  extensions=RIG), extensions=RIG, seed=0)
        for _ in range(2)
    ]  # fmt: skip
    first, second = plays
    assert ((first.actions >= DO_NOTHING) & (first.actions < 8)).all()
    assert ((first.returns >= 0) & (first.returns <= 1)).all()
    np.testing.assert_array_equal(first.actions, second.actions)
    np.testing.assert_array_equal(first.returns, second.returns)


def test_an_unexplained_spike_costs_the_poisson_tail_of_the_inputs_it_needs():
    """By hand: at rate r the chance of k or more spontaneous inputs, at least the floor;
    silence its complement; without background input, impossible and certain."""
    from spikectl.planning.spike_likelihood import _poisson_tails

    r = 0.01
    spike, silent = _poisson_tails(r, 0.0)
    one, two = 1 - np.exp(-r), 1 - np.exp(-r) * (1 + r)
    np.testing.assert_allclose(np.exp(spike[1:3]), [one, two], rtol=1e-9)
    np.testing.assert_allclose(np.exp(silent[1:3]), [1 - one, 1 - two], rtol=1e-9)
    floored = np.exp(_poisson_tails(r, one)[0])
    np.testing.assert_allclose(floored[1:], one, rtol=1e-12)  # the default: one input's chance
    spike, silent = _poisson_tails(0.0, 0.0)
    assert (spike[1:] == -np.inf).all() and (silent[1:] == 0.0).all()


def test_kept_to_the_true_columns_the_posterior_is_the_network():
    weights = generate_topology(5, np.random.default_rng(7))
    estimate = SpikeLikelihoodFilter(5, PARAMS, 0.005)
    estimate.keep_only(weights)
    signs, known = estimate.weights(0.25)
    np.testing.assert_array_equal(signs, weights)
    assert known.all() and estimate.alive.sum() == 5
    with pytest.raises(ValueError, match="column 0 of weights is no hypothesis"):
        estimate.keep_only(np.eye(5, dtype=np.int8))
    # Told one column: that column alone is the truth; the others keep every hypothesis.
    one = SpikeLikelihoodFilter(5, PARAMS, 0.005)
    one.keep_only(weights, columns=[2])
    signs, known = one.weights(0.25)
    np.testing.assert_array_equal(signs[:, 2], weights[:, 2])
    assert known[:, 2].all() and one.alive[2].sum() == 1
    assert (one.alive[[0, 1, 3, 4]]).all()
    for bad in ([5], [-1], [], [0.5]):
        with pytest.raises(ValueError, match="columns must be neuron indices 0 to 4"):
            one.keep_only(weights, columns=bad)
