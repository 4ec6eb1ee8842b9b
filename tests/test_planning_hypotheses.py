"""Identify-and-plan planning one action sequence on K networks drawn from its estimate
(``DecisionSettings(hypotheses=K)``, the ``rig`` composition's decision rule): the
networks planned on, the draws they share with QMDP, legal and deterministic play, and
K = 1 as the estimate's planning weights alone."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from conftest import play_legally

from spikectl import make_splits
from spikectl.envs.controller import batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.planning import Composition, DecisionSettings, IdentifyAndPlan, QMDPSettings
from spikectl.planning.deciding import Situation

HYPOTHESES4 = Composition("hypotheses4", decision=DecisionSettings(hypotheses=4))


@pytest.mark.parametrize("bad", [0, -2, 1.5, True, "4"])
def test_hypotheses_must_be_a_positive_integer(bad):
    with pytest.raises(ValueError, match="hypotheses must be an integer >= 1, got"):
        DecisionSettings(hypotheses=bad)


def test_the_draws_cover_qmdp_and_the_hypotheses():
    assert DecisionSettings().draws == 0
    assert DecisionSettings(hypotheses=1).draws == 0
    assert DecisionSettings(hypotheses=8).draws == 8
    assert DecisionSettings(hypotheses=8, gamble=QMDPSettings(networks=16)).draws == 16
    assert DecisionSettings(hypotheses=32, gamble=QMDPSettings(networks=16)).draws == 32


def test_the_plan_is_made_on_k_networks_drawn_from_the_estimate():
    contexts = make_splits(4, 4, 6, seed=2)[1]
    policy = IdentifyAndPlan(composition=HYPOTHESES4)
    env = gym.make("spikectl/NeuronControl-v0", contexts=contexts).unwrapped
    observation, info = env.reset(seed=0, options={"context": 0})
    for _ in range(5):  # some evidence, so that some entries are known
        observation, _, _, _, info = env.step(policy.act(observation, info))
    policy.act(observation, info)
    weights, known = policy.planning_weights()
    situation = Situation(int(observation["step"]), int(observation["target"]),
                          np.asarray(observation["pattern"]), info["action_mask"])  # fmt: skip
    model = policy.composition.decision.planning_model(policy, weights, situation)
    assert model.weights.shape == (4, 6, 6)
    expected = policy.estimate.sample(policy.known_sd, policy.uniforms[0][:4],
                                      policy.uniforms[1][:4])  # fmt: skip
    np.testing.assert_array_equal(model.weights, expected)
    assert np.isin(model.weights, (-1, 0, 1)).all()
    signs = policy.estimate.weights(policy.known_sd)[0]
    for drawn in model.weights:  # the known entries are the estimate's in every draw
        np.testing.assert_array_equal(drawn[known], signs[known])


def test_hypotheses_play_legally_deterministically_and_one_is_the_estimate():
    env = gym.make("spikectl/NeuronControl-v0", contexts={"n_train": 4, "n_test": 4})
    play_legally(env, IdentifyAndPlan(composition=HYPOTHESES4), range(2))
    train = make_splits(6, 1, 8, seed=0)[0]
    first = evaluate_policy(train, batched(IdentifyAndPlan(composition=HYPOTHESES4)))
    second = evaluate_policy(train, batched(IdentifyAndPlan(composition=HYPOTHESES4)))
    np.testing.assert_array_equal(first.actions, second.actions)
    plain = evaluate_policy(train, batched(IdentifyAndPlan()))
    assert not np.array_equal(first.actions, plain.actions)
    one = Composition("one", decision=DecisionSettings(hypotheses=1))
    np.testing.assert_array_equal(
        evaluate_policy(train, batched(IdentifyAndPlan(composition=one))).actions, plain.actions
    )
