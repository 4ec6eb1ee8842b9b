"""The expected-return (QMDP) choice of identify-and-plan: values by hand, the batched
continuation search against the planner's, and the policy option."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import play_legally, spike_pattern

from spikectl import IdentifyAndPlan, NeuronParams, make_splits
from spikectl.contexts.generation import legal_actions
from spikectl.envs.controller import batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.simulator import SimulatorState
from spikectl.planning import (
    Composition,
    DecisionSettings,
    PlanningModel,
    QMDPSettings,
    beam_search,
)
from spikectl.planning.qmdp import (
    Episode,
    best_returns,
    context_likelihood,
    expected_returns,
    synapse_entropy,
)

PARAMS = NeuronParams()


def gambling(settings: QMDPSettings, width: int = 32) -> Composition:
    """The paper's composition choosing by expected return where it would probe."""
    return Composition("gamble", decision=DecisionSettings(width=width, gamble=settings))


@pytest.mark.parametrize(("width", "horizon"), [(8, 10), (32, 60)])
def test_best_returns_is_the_beam_search_return(splits, width, horizon):
    # One problem per training network, all searched at once: each must get exactly the
    # return of the planner's own beam search on that network alone.
    train, _ = splits
    contexts = list(train[:8])
    expected, found = [], []
    for context in contexts:
        legal = legal_actions(8, context.target).astype(np.int64)
        model = PlanningModel(context.weights[None].copy(), context.target, legal, PARAMS)
        start = SimulatorState.at_rest(1, 8, PARAMS)
        expected.append(beam_search(model, start, context.pattern, 0, width, horizon))
        weights = context.weights[None].copy()
        episode = Episode(context.pattern, context.target, legal, PARAMS)
        found.append(best_returns(weights, start, episode, 0, horizon, width)[0])
    assert np.allclose(found, [plan.predicted_return for plan in expected], atol=1e-12)
    # Batched: problems of one pattern and target, different networks, one call.
    context = contexts[0]
    weights = np.stack([c.weights for c in contexts])  # [P, n, n]
    start = SimulatorState.at_rest(len(contexts), 8, PARAMS)
    legal = legal_actions(8, context.target).astype(np.int64)
    episode = Episode(context.pattern, context.target, legal, PARAMS)
    batched = best_returns(weights, start, episode, 0, horizon, width)
    alone = [
        best_returns(w[None].copy(), SimulatorState.at_rest(1, 8, PARAMS), episode, 0,
                     horizon, width)[0]
        for w in weights
    ]  # fmt: skip
    assert np.array_equal(batched, alone)


def test_expected_returns_by_hand():
    # Network A: 0 -> 2 excitatory; network B: 1 -> 2 excitatory; weights 3 : 1. The
    # target (2) must spike at step 1 only (m = 1, N = 4: a wanted spike is worth 0.5,
    # a wanted silence 0.5 / 3). From rest, stimulating an excitatory input at step 0
    # makes the target spike at step 1 (-70 + 20 mV = threshold); it is refractory at
    # step 2. Over steps 0..2: Q(a) = 2 * 0.5 / 3 + 0.5 * P(a excites the target).
    networks = np.zeros((2, 3, 3), dtype=np.int8)
    networks[0, 0, 2] = 1
    networks[1, 1, 2] = 1
    pattern = spike_pattern(4, [1])
    actions = np.array([-1, 0, 1], dtype=np.int64)
    episode = Episode(pattern, 2, actions, PARAMS)
    values = expected_returns(
        networks, np.array([3.0, 1.0]), SimulatorState.at_rest(1, 3, PARAMS), actions,
        episode, step=0, settings=QMDPSettings(horizon=3, width=4),
    )  # fmt: skip
    silent = 0.5 / 3
    assert np.allclose(values, [2 * silent, 2 * silent + 0.75 * 0.5, 2 * silent + 0.25 * 0.5])
    # Horizon 1 values the step itself only: nothing reaches the target within it.
    values = expected_returns(
        networks, np.array([3.0, 1.0]), SimulatorState.at_rest(1, 3, PARAMS), actions,
        episode, step=0, settings=QMDPSettings(horizon=1, width=4),
    )  # fmt: skip
    assert np.allclose(values, silent)
    with pytest.raises(ValueError, match="positive sum"):
        expected_returns(networks, np.zeros(2), SimulatorState.at_rest(1, 3, PARAMS),
                         actions, episode, 0, QMDPSettings(horizon=3, width=4))  # fmt: skip
    with pytest.raises(ValueError, match="horizon"):
        QMDPSettings(horizon=0)


def test_context_likelihood_by_hand():
    # Network 0: 0 -> 2 and 1 -> 2 excitatory, 3 -> 0 excitatory: neurons 0 and 2 have
    # an excitatory input (the target is drawn among 2), the target has 2 of them (4
    # random actions: 3 neurons and do nothing). Network 1: the target's only input is
    # inhibitory, so the generator could not have chosen it.
    networks = np.zeros((2, 4, 4), dtype=np.int8)
    networks[0, 0, 2] = networks[0, 1, 2] = networks[0, 3, 0] = 1
    networks[1, 0, 2] = -1
    networks[1, 1, 3] = 1
    spike_at_1 = context_likelihood(networks, 2, spike_pattern(10, [1]), n_actions=4)
    assert np.allclose(spike_at_1, [0.5 * 2 / 4, 0.0])
    no_spike_at_1 = context_likelihood(networks, 2, spike_pattern(10, [3]), n_actions=4)
    assert np.allclose(no_spike_at_1, [0.5 * (1 - 2 / 4), 0.0])


def test_synapse_entropy_by_hand():
    columns = np.array([[1, 0, -1], [0, 0, 1]], dtype=np.int8)  # [K = 2, n = 3]
    entropy = synapse_entropy(columns, np.array([3.0, 1.0]))
    quarter = -(0.75 * np.log(0.75) + 0.25 * np.log(0.25))
    assert np.allclose(entropy, [quarter, 0.0, quarter])


def test_gamble_option_is_legal_deterministic_and_checked(splits):
    train, _ = splits
    policy = IdentifyAndPlan(composition=gambling(QMDPSettings(networks=4, width=4, horizon=5)))
    vector = batched(policy)
    first = evaluate_policy(train[:4], vector)  # the environment raises on illegal actions
    second = evaluate_policy(train[:4], batched(policy))
    assert np.array_equal(first.actions, second.actions)
    assert np.array_equal(first.returns, second.returns)
    assert sum(copy.gambles for copy in vector.copies) > 0  # the option was exercised
    for name in ("networks", "horizon", "width", "candidates"):
        with pytest.raises(ValueError, match=f"{name} must be an integer"):
            QMDPSettings(**{name: -1})
    with pytest.raises(ValueError, match="information"):
        QMDPSettings(information=-0.1)
    with pytest.raises(TypeError, match="gamble must be a QMDPSettings"):
        DecisionSettings(gamble={"networks": 4})


def test_gamble_values_a_subset_of_actions_on_larger_networks():
    # n = 16 with at most 4 candidates valued: every action taken stays legal.
    train, _ = make_splits(3, 3, 16, seed=1)
    policy = IdentifyAndPlan(composition=gambling(
        QMDPSettings(networks=4, width=2, horizon=4, candidates=4), width=8
    ))  # fmt: skip
    vector = batched(policy)
    episodes = evaluate_policy(train, vector)
    assert sum(copy.gambles for copy in vector.copies) > 0
    assert np.all((episodes.returns >= 0) & (episodes.returns <= 1 + 1e-12))


@pytest.mark.parametrize(
    ("env_id", "extensions"),
    [("spikectl/NeuronControlPartial-v0", None),
     ("spikectl/NeuronControl-v0", {"observation_noise_mV": 2.0, "stochastic_release": True})],
)  # fmt: skip
def test_gamble_never_takes_an_illegal_action_under_extensions(env_id, extensions):
    # Hidden neurons and noise break what the drawn networks assume; the choice must
    # still be one of the legal actions (the environment raises otherwise).
    kwargs = {} if extensions is None else {"extensions": extensions}
    env = gym.make(env_id, contexts={"n_train": 3, "n_test": 3}, **kwargs)
    policy = IdentifyAndPlan(composition=gambling(QMDPSettings(networks=4, width=2, horizon=4),
                                                  width=8),
                             extensions=env.unwrapped.extensions)  # fmt: skip
    gambles = 0
    for episode in range(2):
        play_legally(env, policy, [episode])
        gambles += policy.gambles
    assert gambles > 0
