"""The exact posterior under the task's observation model (spikectl.planning.bayes):
values on hand-built 3-neuron cases, computed here by enumerating the 9 columns."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning import Composition, EstimatorSettings, IdentifyAndPlan, ObservationSettings
from spikectl.planning.bayes import (
    BayesConnectivityEstimate,
    ObservationModel,
    release_chances,
)
from spikectl.planning.discrete import (
    _OUTLIER_RANGE,
    MIN_RESIDUAL_SD,
    OUTLIER_PROBABILITY,
    DiscreteConnectivityEstimate,
)

PARAMS = NeuronParams()
TASK_MODEL = Composition("task-model", observation=ObservationSettings(task_model=True))
BAYES = TASK_MODEL.but("bayes", estimator=EstimatorSettings("bayes"))
FILTERED = TASK_MODEL.but("filtered", observation=ObservationSettings(True, filter_voltage=True))


def normal(x, mean, sd):
    return math.exp(-0.5 * ((x - mean) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))


def column_posterior(likelihood) -> dict[tuple[int, int], float]:
    """P(G[0, 2], G[1, 2] | evidence) by enumeration, with the generator's prior
    (neuron 0 at distance 2, neuron 1 at distance 1 from neuron 2)."""
    p = connection_probability(np.array([2, 1]))
    prior = {-1: p * (1 - EXCITATORY_PROBABILITY), 0: 1 - p, 1: p * EXCITATORY_PROBABILITY}
    joint = {
        (a, b): prior[a][0] * prior[b][1] * likelihood(a, b)
        for a, b in itertools.product((-1, 0, 1), repeat=2)
    }
    total = sum(joint.values())
    return {key: value / total for key, value in joint.items()}


def estimate_posterior(estimate, released, residual) -> dict[tuple[int, int], float]:
    """Column 2's posterior: the prior times :meth:`log_likelihood` (before ``add``
    applies Dale's law across columns)."""
    observed = np.array([False, False, True])
    log_weights = (
        estimate.log_weights[2]
        + estimate.log_likelihood(
            np.asarray(released, dtype=float), np.array([0.0, 0.0, residual]), observed
        )[0]
    )
    weights = np.exp(log_weights - log_weights.max())
    weights /= weights.sum()
    columns = estimate.hypotheses[2]  # [M, pre]
    return {(int(c[0]), int(c[1])): float(w) for c, w in zip(columns, weights, strict=True)}


def outlier_mixed(density: float) -> float:
    return (1 - OUTLIER_PROBABILITY) * density + OUTLIER_PROBABILITY / _OUTLIER_RANGE


def test_observation_model_reads_the_task():
    extensions = Extensions(observation_noise_mV=2.0, stochastic_release=True,
                            background_rate=0.005, synaptic_spread=0.1)  # fmt: skip
    model = ObservationModel.of(extensions, PARAMS)
    assert model.stochastic_release and model.synaptic_spread == 0.1
    assert model.background_probability == pytest.approx(1 - math.exp(-0.005))
    assert model.background_step == pytest.approx(1.0)
    sd = 2.0 * math.hypot(1.0, 1.0 - PARAMS.leak_per_step) / PARAMS.synaptic_step_mV
    assert model.residual_sd(PARAMS) == pytest.approx(sd)
    assert ObservationModel.of(None, PARAMS).residual_sd(PARAMS) == MIN_RESIDUAL_SD


def test_release_chances_follow_the_release_rule():
    spiked = np.array([True, True, False])
    chances = release_chances(spiked, np.array([5, 1, 9]), PARAMS)
    rule = PARAMS.release_scale * (1 - np.exp(-np.array([5.0, 1.0]) * PARAMS.recovery_per_step))
    np.testing.assert_allclose(chances, [rule[0], rule[1], 0.0])


def test_paper_model_is_the_discrete_posterior():
    """Without extensions the likelihood is the discrete estimate's (same log weights)."""
    rng = np.random.default_rng(3)
    bayes = BayesConnectivityEstimate(5, ObservationModel(), PARAMS)
    discrete = DiscreteConnectivityEstimate(5, MIN_RESIDUAL_SD)
    for _ in range(12):
        released = (rng.random(5) < 0.4).astype(float)
        residual = rng.integers(-1, 2, 5) + 0.05 * rng.standard_normal(5)
        observed = rng.random(5) < 0.8
        bayes.add(released, residual, observed)
        discrete.add(released, residual, observed)
    np.testing.assert_allclose(bayes.log_weights, discrete.log_weights, atol=1e-9)
    np.testing.assert_allclose(bayes.posterior()[0], discrete.posterior()[0], atol=1e-12)


def test_stochastic_release_posterior_values():
    """Neuron 0 spiked with release chance 0.4; neuron 2 then rose by one synapse (1.0)
    or not at all (0.0): P(G[:, 2]) against hand enumeration."""
    model = ObservationModel(stochastic_release=True)
    sd = model.residual_sd(PARAMS)
    for residual in (1.0, 0.0):
        estimate = BayesConnectivityEstimate(3, model, PARAMS)

        def likelihood(a, b, residual=residual):
            return outlier_mixed(0.4 * normal(residual, a, sd) + 0.6 * normal(residual, 0, sd))

        expected = column_posterior(likelihood)
        got = estimate_posterior(estimate, [0.4, 0.0, 0.0], residual)
        for key, value in expected.items():
            assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12)
    # A silent residual leaves an excitatory synapse possible (the release may have
    # failed): P(G[0, 2] = +1) is 0.6 / (0.6 + ...) of its prior odds, not ruled out.
    plus = sum(v for (a, _), v in expected.items() if a == 1)
    assert 0.05 < plus < connection_probability(np.array([2]))[0] * EXCITATORY_PROBABILITY


def test_two_uncertain_releases_enumerate_four_subsets():
    model = ObservationModel(stochastic_release=True)
    sd = model.residual_sd(PARAMS)
    estimate = BayesConnectivityEstimate(3, model, PARAMS)

    def likelihood(a, b):
        total = 0.0
        for x, y in itertools.product((0, 1), repeat=2):
            chance = (0.3 if x else 0.7) * (0.6 if y else 0.4)
            total += chance * normal(1.0, a * x + b * y, sd)
        return outlier_mixed(total)

    expected = column_posterior(likelihood)
    got = estimate_posterior(estimate, [0.3, 0.6, 0.0], 1.0)
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12)


def test_add_is_the_likelihood_then_dale():
    """add() multiplies in the likelihood; a row whose sign becomes certain (here row 0,
    excitatory, from a full one-synapse rise) then rules out the other sign in every
    column, as the discrete estimate does."""
    estimate = BayesConnectivityEstimate(3, ObservationModel(stochastic_release=True), PARAMS)
    before = estimate.log_weights.copy()
    released, observed = np.array([0.9, 0.0, 0.0]), np.array([False, False, True])
    residual = np.array([0.0, 0.0, 1.0])
    likelihood = estimate.log_likelihood(released, residual, observed)[0]
    estimate.add(released, residual, observed)
    mean, _ = estimate.posterior()
    assert mean[0, 2] > 0.99
    rows = estimate.hypotheses[2][:, 0]
    keep = rows != -1
    updated = before[2] + likelihood
    np.testing.assert_allclose(
        estimate.log_weights[2][keep] - estimate.log_weights[2][keep].max(),
        updated[keep] - updated[keep].max(), atol=1e-9,
    )  # fmt: skip
    # Column 1 saw nothing, but Dale's law removed its inhibitory-from-0 hypotheses.
    assert estimate.posterior()[0][0, 1] >= 0


def test_background_and_spread_posterior_values():
    """A sure release of neuron 1 and a residual of 2: two inputs, one of them maybe a
    spontaneous one; each synapse's strength spread by 10 %."""
    model = ObservationModel(noise_mV=1.0, background_probability=0.01, background_step=1.0,
                             synaptic_spread=0.1)  # fmt: skip
    sd = model.residual_sd(PARAMS)
    estimate = BayesConnectivityEstimate(3, model, PARAMS)

    def likelihood(a, b):
        s = math.sqrt(sd**2 + abs(b) * 0.01 / 3)
        return outlier_mixed(0.99 * normal(2.0, b, s) + 0.01 * normal(2.0, b + 1, s))

    expected = column_posterior(likelihood)
    got = estimate_posterior(estimate, [0.0, 1.0, 0.0], 2.0)
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12)
    # The background explains the excess: an excitatory synapse becomes the likeliest
    # column; without background only the outlier part explains a residual of 2.
    without = estimate_posterior(
        BayesConnectivityEstimate(3, ObservationModel(noise_mV=1.0, synaptic_spread=0.1),
                                  PARAMS), [0.0, 1.0, 0.0], 2.0)  # fmt: skip
    excitatory = sum(v for (_, b), v in got.items() if b == 1)
    assert excitatory > 0.8 > sum(v for (_, b), v in without.items() if b == 1)


def play(policy, env, context):
    observation, info = env.reset(seed=0, options={"context": context})
    policy.reset()
    actions, total, done = [], 0.0, False
    while not done:
        action = policy.act(observation, info)
        assert info["action_mask"][action + 1]
        actions.append(action)
        observation, reward, terminated, truncated, info = env.step(action)
        total += reward
        done = terminated or truncated
    return actions, total


def test_bayes_policy_plays_stochastic_release_deterministically():
    from spikectl.contexts import make_splits
    from spikectl.envs.env import NeuronControlEnv

    extensions = Extensions(stochastic_release=True)
    contexts, _ = make_splits(3, 1, 8, 60, seed=5)
    env = NeuronControlEnv(contexts=contexts, params=PARAMS, extensions=extensions)
    policy = IdentifyAndPlan(PARAMS, BAYES, extensions=extensions)
    first = [play(policy, env, c) for c in range(3)]
    again = [play(policy.spawn(0), env, c) for c in range(3)]
    assert first == again
    assert isinstance(policy.estimate, BayesConnectivityEstimate)
    assert policy.estimate.observations > 0


def test_bayes_falls_back_to_gaussian_beyond_exact_size():
    from spikectl.planning.identify import ConnectivityEstimate

    policy = IdentifyAndPlan(PARAMS, BAYES)
    assert isinstance(policy._new_estimate(16), ConnectivityEstimate)


def test_filtered_state_values():
    """The per-neuron Kalman filter on hand-computed steps (noise 2 mV, prior variance
    0 at rest plus the model's 0.25 mV^2 per step)."""
    from spikectl.planning.filtering import MODEL_VARIANCE_MV2, FilteredState

    tracker = FilteredState(2, PARAMS, noise_mV=2.0, spike_margin_sd=2.0)
    # Step 1: neuron 0 stimulated (+40 mV -> -30 mV, a spike); neuron 1 at rest, seen at -69.
    released, residual, observed = tracker.observe(np.array([-31.0, -69.0]), 0)
    gain = MODEL_VARIANCE_MV2 / (MODEL_VARIANCE_MV2 + 4.0)
    assert tracker.filtered[1] == pytest.approx(-70.0 + gain * 1.0)
    assert tracker.filtered[0] == pytest.approx(-30.0 + gain * -1.0)
    assert tracker.spiked.tolist() == [True, False]
    assert tracker.state.voltage_mV[0, 0] == PARAMS.v_rest_mV
    assert tracker.variance[0] == 0.0
    assert tracker.variance[1] == pytest.approx((1 - gain) * MODEL_VARIANCE_MV2)
    # The residuals are the raw observations against the no-synapse step.
    np.testing.assert_allclose(residual, [(-31.0 - -30.0) / 20.0, (-69.0 - -70.0) / 20.0])
    assert released.tolist() == [0.0, 0.0] and observed.tolist() == [True, True]
    # Step 2: neuron 0 released onto neuron 1 (weight +1 known exactly): predicted
    # -70 + 20 mV from its filtered potential; seen 3 mV low, it is still read as a spike.
    v1, p1 = tracker.filtered[1], tracker.variance[1]
    mean, sd = np.array([[0.0, 1.0], [0.0, 0.0]]), np.zeros((2, 2))
    tracker.observe(np.array([-70.0, -53.0]), -1, (mean, sd))
    predicted = v1 - (v1 - PARAMS.v_rest_mV) * PARAMS.leak_per_step + 20.0
    prior = (1 - PARAMS.leak_per_step) ** 2 * p1 + MODEL_VARIANCE_MV2
    k = prior / (prior + 4.0)
    assert tracker.filtered[1] == pytest.approx(predicted + k * (-53.0 - predicted))
    assert tracker.spiked[1]  # raw -53 mV would not be a spike without a 3 mV margin


def test_the_filter_plans_spikes_within_its_margin_of_the_threshold():
    """Neuron 0 excites the target (2); the target's filtered potential is 0.3 mV below
    rest, where unknown weights can leave it: the paper's neurons need the whole
    20 mV to the threshold and the planner gives the wanted spike up; the filter's
    neurons (spiking from 2 x 2 mV below it) plan it, stimulating 0 at step 1."""
    from spikectl.neuron.simulator import SimulatorState
    from spikectl.planning.beam import PlanningModel, beam_search
    from spikectl.planning.filtering import FilteredState

    tracker = FilteredState(3, PARAMS, noise_mV=2.0, spike_margin_sd=2.0)
    neurons = tracker.neurons()
    assert neurons.shape == (1, 2, 3)
    assert neurons[0, 0] == pytest.approx(PARAMS.v_spike_mV - 4.0)  # V_th less 2 x 2 mV
    assert neurons[0, 1] == pytest.approx(PARAMS.leak_per_step)
    weights = np.zeros((1, 3, 3), dtype=np.int8)
    weights[0, 0, 2] = 1
    state = SimulatorState.at_rest(1, 3, PARAMS)
    state.voltage_mV[0, 2] = PARAMS.v_rest_mV - 0.3
    pattern = np.zeros(60, dtype=bool)
    pattern[2] = True  # stimulated at step 1, neuron 0's release reaches 2 at step 2
    actions = np.array([-1, 0, 1], dtype=np.int64)
    plans = {}
    for label, kind in (("paper", None), ("filter", neurons)):
        model = PlanningModel(weights, 2, actions, PARAMS, kind)
        plans[label] = beam_search(model, state.copy(), pattern, 0, 8, 10)
    assert plans["paper"].rewards[2] == 0  # predicted at -50.3 mV: no spike
    assert plans["filter"].rewards[2] == pytest.approx(0.5)  # R_max / m, m = 1
    assert plans["filter"].actions[1] == 0


def test_model_variance_is_zero_only_under_the_papers_dynamics():
    """The filter trusts the model's step exactly where only the observation differs from
    the paper (noise, bleaching) and keeps its extra variance where the step is wrong or
    random."""
    from spikectl.planning.filtering import MODEL_VARIANCE_MV2, model_variance

    assert model_variance(None) == 0.0
    assert model_variance(Extensions(observation_noise_mV=2.0)) == 0.0
    assert model_variance(Extensions(bleaching_time_constant_steps=100.0)) == 0.0
    for unmodelled in (
        {"hidden_neurons": 2}, {"hidden_fraction": 0.25}, {"threshold_spread": 0.1},
        {"time_constant_spread": 0.1}, {"synaptic_spread": 0.1}, {"stochastic_release": True},
        {"background_rate": 0.005},
    ):  # fmt: skip
        extensions = Extensions(observation_noise_mV=1.0, **unmodelled)
        assert model_variance(extensions) == MODEL_VARIANCE_MV2, unmodelled
    with pytest.raises(ValueError, match="model_variance_mV2 must be >= 0"):
        from spikectl.planning.filtering import FilteredState

        FilteredState(2, PARAMS, noise_mV=1.0, spike_margin_sd=2.0, model_variance_mV2=-1.0)


@pytest.mark.parametrize("noise_mV", [1.0, 4.0])
def test_told_the_weights_the_filter_is_exact_under_noise(noise_mV):
    """Under the paper's dynamics the filtered potentials of the loop told the weights are
    the network's own, step by step, whatever the noise (the noise cannot move a resting
    neuron or one landing exactly on the threshold), so it plays the actions it plays
    without noise, told the weights."""
    from spikectl.contexts import make_splits
    from spikectl.envs.controller import play_episode
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.neuron.simulator import simulate

    contexts, _ = make_splits(4, 1, 8, 60, seed=11)
    noise = Extensions(observation_noise_mV=noise_mV)
    noisy = NeuronControlEnv(contexts=contexts, extensions=noise)
    exact = NeuronControlEnv(contexts=contexts)
    for index in range(len(contexts)):
        weights = contexts[index].weights
        told = IdentifyAndPlan(PARAMS, FILTERED, extensions=noise, told_weights=weights)
        seen: list[np.ndarray] = []
        act = told.act

        def recording(observation, info, act=act, seen=seen, told=told):
            action = act(observation, info)
            seen.append((told.reader.tracker.filtered.copy(), told.reader.tracker.spiked.copy()))
            return action

        told.act = recording
        actions, _ = play_episode(noisy, told, index, seed=3)
        potentials, spikes = simulate(weights, actions, PARAMS)  # [N, n] each
        # What the filter holds at step t + 1 is the network after step t: its spikes, and
        # its potential wherever it was not held refractory.
        filtered = np.stack([potential for potential, _ in seen[1:]])  # [N - 1, n]
        read = np.stack([spiked for _, spiked in seen[1:]])
        np.testing.assert_array_equal(read, spikes[:-1])
        refractory = np.zeros_like(spikes)
        for lag in range(1, PARAMS.refractory_steps + 1):
            refractory[lag:] |= spikes[:-lag]
        free = ~refractory[:-1]
        np.testing.assert_array_equal(filtered[free], potentials[:-1][free])
        plain, _ = play_episode(exact, IdentifyAndPlan(PARAMS, told_weights=weights), index)
        np.testing.assert_array_equal(actions, plain)


def test_named_controller_takes_the_environments_observation_model():
    """`identify-and-plan` by name plays the Bayes model where the environment changes
    what an observation means, and the paper's composition (the guided learner's
    teacher) on the paper's environment (tests/test_named_compositions.py has the rule)."""
    from spikectl.contexts import make_splits
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.planning.named import KNOWN_SD_LARGE
    from spikectl.training.loaders import load_controller

    contexts, _ = make_splits(2, 1, 8, 60, seed=5)
    noisy = Extensions(observation_noise_mV=2.0)
    controller = load_controller(
        "identify-and-plan", env=NeuronControlEnv(contexts=contexts, extensions=noisy)
    )
    assert controller.composition.name == "noise"
    assert controller.observation.extensions == noisy and controller.noise_mV == 2.0
    assert isinstance(controller.observation.model, ObservationModel)
    assert controller.observation.model.noise_mV == 2.0
    plain = load_controller("identify-and-plan", env=NeuronControlEnv(contexts=contexts))
    assert plain.composition.name == "paper" and plain.observation.extensions is None
    assert plain.known_sd == 0.25 and controller.known_sd == 0.25
    assert plain.composition.decision.gamble is None  # n = 8: no QMDP
    # From 16 observed neurons on, QMDP where it would probe and an earlier commitment.
    large, _ = make_splits(2, 1, 16, 60, seed=5)
    controller = load_controller("identify-and-plan", contexts=large)
    assert controller.composition.name == "paper-16"
    assert controller.composition.decision.gamble.networks == 16
    assert controller.known_sd == KNOWN_SD_LARGE


def test_gaussian_estimate_learns_from_release_chances_under_noise():
    """Told stochastic release under measurement noise (residuals not exact, so nothing
    settles a release: tests/test_planning_release.py has the noise-free case), the
    Gaussian estimate's evidence is each spike's release chance (the rule's
    probability), not the deterministic rule's 0/1."""
    from spikectl.contexts import make_splits
    from spikectl.envs.env import NeuronControlEnv

    extensions = Extensions(stochastic_release=True, observation_noise_mV=1.0)
    contexts, _ = make_splits(1, 1, 8, 60, seed=2)
    env = NeuronControlEnv(contexts=contexts, params=PARAMS, extensions=extensions)
    policy = IdentifyAndPlan(PARAMS, TASK_MODEL, extensions=extensions)
    seen = []
    add = None

    def record(released, residual, observed):
        seen.append(np.asarray(released, dtype=float).copy())
        add(released, residual, observed)

    observation, info = env.reset(seed=0, options={"context": 0})
    policy.reset()
    for _ in range(20):
        action = policy.act(observation, info)
        if add is None:
            add = policy.estimate.add
            policy.estimate.add = record
        observation, _, _, _, info = env.step(action)
    chances = np.concatenate(seen)
    assert np.any((chances > 0) & (chances < 1))  # fractional chances reached the estimate
    assert chances.max() <= PARAMS.release_scale + 1e-12
