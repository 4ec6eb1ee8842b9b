"""Identify-and-plan's identification of the target's inputs as per-neuron features
(``spikectl.planning.belief``): values on a hand-built network, row independence,
refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_planning import feed_forward_probe

import spikectl
from spikectl.contexts.generation import connection_probability
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.params import NeuronParams
from spikectl.planning.belief import BELIEF_FEATURES, TargetInputBelief, episode_beliefs


def _episode(weights: np.ndarray, actions: list[int]) -> tuple[np.ndarray, ...]:
    """(voltage [1, N + 1, n] from rest, actions [1, N], an empty pattern [1, N], every
    action legal [1, n + 1]) of one noise-free episode: the belief reads neither of the
    last two."""
    params = NeuronParams()
    after, _ = spikectl.simulate(weights, np.array(actions), params)  # [N, n] after each step
    n = weights.shape[0]
    rest = np.full((1, n), params.v_rest_mV)
    voltage = np.concatenate([rest, after]).astype(np.float32)[None]  # [1, N + 1, n]
    return voltage, np.array([actions]), np.zeros((1, len(actions))), np.ones((1, n + 1))


def test_the_belief_names_the_targets_inputs_on_a_hand_built_network():
    # Target 4 has excitatory inputs 1, 3 and 5. Stimulating 0, 1, 2 and 3 in turn
    # releases 0..4 (alone or told apart), so their synapses onto 4 become known; 5 never
    # releases, so its entry keeps the generator's prior.
    weights, actions = feed_forward_probe()
    voltage, played, pattern, legal = _episode(weights, actions)
    features = episode_beliefs(
        TargetInputBelief(NeuronParams()), voltage, played, np.array([4]), pattern, legal
    )
    assert features.shape == (1, len(actions) + 1, 6, len(BELIEF_FEATURES))
    excites, inhibits, uncertainty = np.moveaxis(features[0, -1], -1, 0)  # [n] each
    np.testing.assert_allclose(excites[[1, 3]], 1.0, atol=1e-6)
    np.testing.assert_allclose(excites[[0, 2]], 0.0, atol=1e-6)
    np.testing.assert_allclose(inhibits[:4], 0.0, atol=1e-6)
    assert (uncertainty[:4] < 0.05).all()
    # Neuron 5 (distance 1 from the target): the prior N(0, p), p = 0.3, untouched.
    prior_sd = math.sqrt(connection_probability(np.array(1)))
    untouched = 0.5 * math.erfc(0.5 / (prior_sd * math.sqrt(2)))
    assert excites[5] == pytest.approx(untouched, rel=1e-6)
    assert inhibits[5] == pytest.approx(untouched, rel=1e-6)
    assert uncertainty[5] == pytest.approx(1.0, abs=1e-9)
    # Before any observation every neuron is at its prior (the target's own entry too).
    assert np.all(features[0, 0, :, 2] == 1.0)
    # The features are read from observations only: the same episode with another
    # neuron named the target gives that neuron's column.
    column_3 = episode_beliefs(
        TargetInputBelief(NeuronParams()), voltage, played, np.array([3]), pattern, legal
    )
    np.testing.assert_allclose(column_3[0, -1, [1], 0], 1.0, atol=1e-6)  # 1 excites 3
    np.testing.assert_allclose(column_3[0, -1, [2], 1], 1.0, atol=1e-6)  # 2 inhibits 3


def test_a_rows_belief_does_not_depend_on_its_batch(splits):
    episodes = evaluate_policy(splits[1], spikectl.IdentifyAndPlan(NeuronParams()))
    targets = np.array([c.target for c in splits[1]])
    patterns = np.stack([c.pattern for c in splits[1]])
    together = episode_beliefs(
        TargetInputBelief(NeuronParams()), episodes.voltage, episodes.actions, targets,
        patterns, episodes.action_mask,
    )  # fmt: skip
    for row in (0, 7):
        one = slice(row, row + 1)
        alone = episode_beliefs(
            TargetInputBelief(NeuronParams()), episodes.voltage[one], episodes.actions[one],
            targets[one], patterns[one], episodes.action_mask[one],
        )  # fmt: skip
        assert np.array_equal(alone[0], together[row])
    # and it learns: at the end the true excitatory inputs stand out
    truth = np.stack([np.sign(c.weights[:, c.target]) for c in splits[1]])  # [S, n]
    final = together[:, -1, :, 0]
    assert final[truth > 0].mean() > 0.8 > 0.1 > final[truth <= 0].mean()


def test_belief_refuses_a_mid_episode_start_and_bad_noise():
    belief = TargetInputBelief(NeuronParams())
    observations = {"voltage": np.full((2, 4), -70.0), "step": np.array([3, 3]),
                    "last_action": np.array([-1, -1]), "target": np.array([0, 1])}  # fmt: skip
    with pytest.raises(ValueError, match="first step"):
        belief(observations)
    with pytest.raises(ValueError, match="noise_mV"):
        TargetInputBelief(NeuronParams(), noise_mV=-1.0)
