"""Identification from spikes alone (spikectl/planning/spike_filter.py, the ``"spikes"``
estimator): hand-computed cases on three neurons, the truth never dropped on random
networks (its potentials the simulator's, exactly), the exact Dale posterior, and
identify-and-plan playing spikes-only sensing (deterministic; refusing in one line what
it cannot read)."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.contexts import Context, ContextSet
from spikectl.contexts.generation import generate_topology
from spikectl.envs.controller import ControllerInputError
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, simulate
from spikectl.planning import Composition, EstimatorSettings, IdentifyAndPlan, named_composition
from spikectl.planning.spike_filter import (
    SpikeFilter,
    SpikeFilterTooLarge,
    SpikesInconsistent,
    SpikeState,
)

PARAMS = NeuronParams()
SPIKES = Extensions(sensing="spikes")


def feed(n: int, spikes: np.ndarray, actions: np.ndarray) -> tuple[SpikeFilter, SpikeState]:
    """A filter and its tracker after the steps of ``spikes`` [T, n] under ``actions`` [T]
    (what identify-and-plan does each step: read, add, follow)."""
    estimate, tracker = SpikeFilter(n, PARAMS), SpikeState(n, PARAMS, 0.0)
    for step_spikes, action in zip(spikes, actions, strict=True):
        estimate.add(*tracker.observe(step_spikes.astype(np.int8), int(action)))
        tracker.follow(estimate)
    return estimate, tracker


def columns(estimate: SpikeFilter, j: int, mask: np.ndarray) -> set[tuple[int, ...]]:
    """The input columns of neuron ``j`` (as tuples over all n) where ``mask[j]``."""
    return {tuple(int(v) for v in h) for h in estimate.hypotheses[j][mask[j]]}


def test_three_neurons_by_hand():
    """Neuron 0 stimulated at rest spikes (-30 mV) and releases; at the next step neuron
    1 spikes (exactly -50 mV: G[0, 1] = +1) and neuron 2 does not (G[0, 2] is 0 or -1).
    Neuron 0 is refractory: its column learns nothing. Neuron 1's survivors make row 0
    excitatory, so Dale's law leaves G[0, 2] = 0 alone with weight."""
    spikes = np.array([[1, 0, 0], [0, 1, 0]])
    estimate, tracker = feed(3, spikes, np.array([0, DO_NOTHING]))
    alive = estimate.alive
    assert columns(estimate, 0, alive) == {(0, a, b) for a in (-1, 0, 1) for b in (-1, 0, 1)}
    assert columns(estimate, 1, alive) == {(1, 0, b) for b in (-1, 0, 1)}
    assert columns(estimate, 2, alive) == {(a, b, 0) for a in (-1, 0) for b in (-1, 0, 1)}
    weighted = estimate.column_weights() > 0
    assert columns(estimate, 2, weighted) == {(0, b, 0) for b in (-1, 0, 1)}
    plus, minus = estimate._marginals()
    assert plus[0, 1] == pytest.approx(1.0) and plus[0, 2] == minus[0, 2] == 0.0
    # Nothing spoke of row 1's and row 2's signs: their entries keep the prior, a
    # connection with probability 0.3 at distance 1, excitatory with probability 0.8.
    assert plus[1, 2] == pytest.approx(0.3 * 0.8) and minus[1, 2] == pytest.approx(0.3 * 0.2)
    assert plus[2, 1] == pytest.approx(0.24) and minus[2, 1] == pytest.approx(0.06)
    # The potentials each surviving column implies: -70 + 0 or -70 - 20 for neuron 2.
    inhibited = [m for m, h in enumerate(estimate.hypotheses[2]) if tuple(h) == (-1, 0, 0)]
    assert estimate.potentials[2, inhibited[0]] == -90.0
    np.testing.assert_array_equal(tracker.state.voltage_mV[0], [-70.0, -70.0, -70.0])
    assert tracker.state.refractory_left[0].tolist() == [0, 1, 0]
    assert tracker.state.released[0].tolist() == [False, True, False]


@pytest.mark.parametrize("fires", [False, True])
def test_an_inhibited_potential_is_remembered(fires):
    """Neuron 0 is stimulated at step 0 (spikes, releases), neuron 1 at step 1 (spikes,
    releases, whatever G[0, 1]). Neuron 2 stays silent at step 1: G[0, 2] is 0 (-70 mV)
    or -1 (-90 mV). At step 2 it gets 20 mV G[1, 2]: from -70 it spikes iff G[1, 2] =
    +1; from -90 it leaks to -89 and cannot (-69 mV at most). A spike at step 2 leaves
    (0, +1) alone; silence the other five columns."""
    spikes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, int(fires)]])
    estimate, _ = feed(3, spikes, np.array([0, 1, DO_NOTHING]))
    if fires:
        expected = {(0, 1, 0)}
    else:
        expected = {(0, -1, 0), (0, 0, 0), (-1, -1, 0), (-1, 0, 0), (-1, 1, 0)}
    assert columns(estimate, 2, estimate.alive) == expected
    assert len(columns(estimate, 1, estimate.alive)) == 9  # stimulated, then refractory
    # Neuron 0 stayed silent at step 2 under neuron 1's release: G[1, 0] is 0 or -1.
    assert columns(estimate, 0, estimate.alive) == {(0, a, b) for a in (-1, 0)
                                                    for b in (-1, 0, 1)}  # fmt: skip
    if not fires:
        m = [m for m, h in enumerate(estimate.hypotheses[2]) if tuple(h) == (-1, 1, 0)][0]
        leaked = -90.0 + (-(-90.0 - PARAMS.v_rest_mV) * PARAMS.leak_per_step + 20.0)
        assert estimate.potentials[2, m] == leaked == pytest.approx(-69.0)


def test_the_prior_is_the_generators_marginals():
    """Before any spike the posterior is the generator's: each entry a connection with its
    distance's probability, excitatory with probability 0.8 (Dale's law keeps the
    marginals)."""
    estimate = SpikeFilter(6, PARAMS)
    plus, minus = estimate._marginals()
    index = np.arange(6)
    from spikectl.contexts.generation import connection_probability

    p = connection_probability(np.abs(index[:, None] - index[None, :]))
    np.fill_diagonal(p, 0.0)
    np.testing.assert_allclose(plus, 0.8 * p, atol=1e-12)
    np.testing.assert_allclose(minus, 0.2 * p, atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_the_true_column_survives_with_its_exact_potential(seed):
    """On random networks under random stimulation the true column of every neuron stays
    alive with positive weight, and its potential is the simulator's bit for bit."""
    rng = np.random.default_rng(seed)
    n, steps = 8, 60
    weights = generate_topology(n, rng)
    actions = np.where(rng.random(steps) < 0.6, rng.integers(0, n, steps), DO_NOTHING)
    voltage, spikes = simulate(weights, actions[None], PARAMS)
    voltage, spikes = voltage[0], spikes[0]
    estimate, tracker = SpikeFilter(n, PARAMS), SpikeState(n, PARAMS, 0.0)
    truth = [int(np.flatnonzero((estimate.hypotheses[j] == weights[:, j]).all(axis=1))[0])
             for j in range(n)]  # fmt: skip
    for t in range(steps):
        estimate.add(*tracker.observe(spikes[t].astype(np.int8), int(actions[t])))
        tracker.follow(estimate)
        after_reset = np.where(spikes[t], PARAMS.v_rest_mV, voltage[t])
        for j in range(n):
            assert estimate.alive[j, truth[j]] and estimate.column_weights()[j, truth[j]] > 0
            assert estimate.potentials[j, truth[j]] == after_reset[j]
    assert estimate.alive.sum() < estimate.alive.size  # the spikes taught something


def test_impossible_spikes_and_large_networks_are_refused():
    with pytest.raises(SpikesInconsistent, match="impossible under every input column"):
        feed(3, np.array([[0, 1, 0]]), np.array([DO_NOTHING]))  # a spike from rest, no input
    with pytest.raises(SpikesInconsistent, match="while refractory"):
        feed(3, np.array([[1, 0, 0], [1, 0, 0]]), np.array([0, 0]))
    with pytest.raises(SpikeFilterTooLarge, match="n = 9 is outside its range of 2 to 8"):
        SpikeFilter(9, PARAMS)


def play(test_set: ContextSet, extensions: Extensions, **kwargs):
    controller = IdentifyAndPlan(test_set.params, named_composition(extensions, 8),
                                 extensions=extensions, **kwargs)  # fmt: skip
    return evaluate_policy(test_set, controller, extensions=extensions, seed=0)


def test_identify_and_plan_plays_spikes_only_deterministically():
    """The named controller plays the ``spikes`` composition; two plays are the same
    episodes; it does better than doing nothing on these networks."""
    test_set = ContextSet.generate(6, n_neurons=8, seed=11)
    assert named_composition(SPIKES, 8).name == "spikes"
    first, second = play(test_set, SPIKES), play(test_set, SPIKES)
    np.testing.assert_array_equal(first.actions, second.actions)
    np.testing.assert_array_equal(first.returns, second.returns)
    assert first.returns.mean() > 0.5


def test_spikes_only_with_what_the_filter_cannot_read_is_refused():
    with pytest.raises(ValueError, match="cannot with hidden_fraction"):
        IdentifyAndPlan(extensions=Extensions(sensing="spikes", hidden_fraction=0.25),
                        composition=named_composition(SPIKES))  # fmt: skip
    with pytest.raises(ValueError, match="cannot with actuator='chr2'"):
        IdentifyAndPlan(extensions=Extensions(sensing="spikes", actuator="chr2"),
                        composition=named_composition(SPIKES))  # fmt: skip
    # The spike filter plays spikes, the others potentials: a mismatch in one line.
    with pytest.raises(ValueError, match="'paper' keeps 'gaussian' on an environment that"):
        IdentifyAndPlan(extensions=SPIKES)
    with pytest.raises(ValueError, match="observes potentials"):
        IdentifyAndPlan(composition=Composition("mine", EstimatorSettings("spikes")))
    with pytest.raises(ValueError, match="without told weights"):
        IdentifyAndPlan(composition=named_composition(SPIKES), extensions=SPIKES,
                        told_weights=np.zeros((8, 8)))  # fmt: skip
    # Built for potentials, shown spikes (or the reverse): one line.
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 1] = 1
    test_set = ContextSet([Context(weights, 1, np.eye(1, 6, 1, dtype=bool)[0])], PARAMS)
    observation, info = NeuronControlEnv(contexts=test_set, extensions=SPIKES).reset(seed=0)
    with pytest.raises(ControllerInputError, match="observes 'voltage'"):
        IdentifyAndPlan(test_set.params).act(observation, info)


def test_identify_and_plan_hits_a_chain_from_spikes():
    """Neuron 0 excites the target 1 (stimulated at rest 0 spikes at once, 1 a step
    later at exactly -50 mV): the pattern's one spike at step 3 is hit once the filter
    has seen it, as with potentials."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 1] = 1
    pattern = np.zeros(12, dtype=bool)
    pattern[[3, 10]] = True
    test_set = ContextSet([Context(weights, 1, pattern)], PARAMS)
    controller = IdentifyAndPlan(PARAMS, named_composition(SPIKES, 3), extensions=SPIKES)
    spiking = evaluate_policy(test_set, controller, extensions=SPIKES, seed=0)
    potentials = evaluate_policy(test_set, IdentifyAndPlan(PARAMS), seed=0)
    assert spiking.returns[0] >= potentials.returns[0] - 1e-12


def test_under_latency_the_truth_survives_with_the_stimulations_that_landed():
    """With one step of latency the evidence is read with the action that landed, not
    the one chosen: every true column survives whole episodes of identify-and-plan."""
    extensions = Extensions(sensing="spikes", latency_steps=1)
    test_set = ContextSet.generate(3, n_neurons=8, seed=5)
    env = NeuronControlEnv(contexts=test_set, extensions=extensions)
    controller = IdentifyAndPlan(test_set.params, named_composition(extensions, 8),
                                 extensions=extensions)  # fmt: skip
    for index in range(len(test_set)):
        observation, info = env.reset(seed=index, options={"context": index})
        controller.reset()
        done = False
        while not done:
            action = controller.act(observation, info)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        estimate, weights = controller.estimate, test_set[index].weights
        for j in range(8):
            truth = (estimate.hypotheses[j] == weights[:, j]).all(axis=1)
            assert estimate.alive[j][truth].all() and truth.any()
        assert estimate.alive.sum() < estimate.alive.size
