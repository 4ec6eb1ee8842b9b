"""The amortised belief over the target's inputs (issue 61): its features read the
neuron model's evidence exactly, the network is permutation-equivariant, causal and the
prior when untrained, and its training is a seeded function of its config."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spikectl.agents.amortised_belief import (
    FEATURES,
    N_FEATURES,
    AmortisedBelief,
    BeliefShapeError,
    belief_features,
    release_history,
    residuals,
)
from spikectl.contexts.generation import connection_probability, generate_topology
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import simulate
from spikectl.training.belief import (
    BeliefTrainingConfig,
    belief_scores,
    synapse_probabilities,
    train_belief,
)
from spikectl.training.belief_episodes import BehaviourMix, belief_batch


def column(features: np.ndarray, name: str) -> np.ndarray:
    return features[..., FEATURES.index(name)]


def test_a_lone_release_shows_its_weight_in_the_targets_residual():
    # 0 -> 2 excitatory; stimulating 0 at step 0 spikes it (-70 + 40 mV >= -50), it
    # releases, and at step 1 the target 2 shows +20 mV: a residual of 1 w_in.
    weights = np.zeros((1, 3, 3), dtype=np.int8)
    weights[0, 0, 2] = 1
    actions = np.array([[0, -1, -1]])
    voltages, spikes = simulate(weights, actions)
    features = belief_features(voltages, spikes, actions, np.array([2]))[0]  # [T, n, F]
    assert column(features, "released_before")[1].tolist() == [1.0, 0.0, 0.0]
    assert column(features, "target_residual")[1].tolist() == [1.0, 1.0, 1.0]
    assert column(features, "released_times_target_residual")[1].tolist() == [1.0, 0.0, 0.0]
    assert column(features, "alone_count")[2].tolist() == pytest.approx([1 / 3, 0.0, 0.0])
    assert column(features, "alone_mean_residual")[2].tolist() == [1.0, 0.0, 0.0]
    assert column(features, "prior")[0].tolist() == pytest.approx([0.3, 0.3, 0.0])
    assert column(features, "is_target")[0].tolist() == [0.0, 0.0, 1.0]


def test_a_spike_within_the_release_interval_releases_nothing():
    # Stimulated at 0, 2 and 7: the spike at 2 comes 2 steps after the release at 0
    # (the interval is 5); the one at 7 comes 7 steps after it.
    params = NeuronParams()
    assert params.min_release_interval_steps == 5
    spikes = np.zeros((1, 8, 2), dtype=bool)
    spikes[0, [0, 2, 7], 0] = True
    released = release_history(spikes, params)[0, :, 0]
    assert np.flatnonzero(released).tolist() == [0, 7]


def test_residuals_equal_the_released_inputs_on_random_networks():
    rng = np.random.default_rng(3)
    weights = np.stack([generate_topology(12, rng) for _ in range(6)])
    actions = rng.integers(-1, 12, size=(6, 40))
    voltages, spikes = simulate(weights, actions)
    params = NeuronParams()
    residual, observed = residuals(voltages, spikes, actions, params)
    released = release_history(spikes, params).astype(float)
    before = np.zeros_like(released)
    before[:, 1:] = released[:, :-1]
    expected = np.einsum("bti,bij->btj", before, weights.astype(float))  # [B, T, n]
    assert np.abs((residual - expected) * observed).max() < 1e-9
    assert observed.mean() > 0.5
    # a neuron that spiked is refractory (unobserved) the next step
    b, t, i = np.nonzero(spikes[:, :-1])
    assert not observed[b, t + 1, i].any()


def random_features(n: int, seed: int = 0) -> torch.Tensor:
    batch = belief_batch(np.random.default_rng(seed), n, 3, 20)
    return torch.from_numpy(batch.features)


def test_permuting_the_neurons_permutes_the_belief():
    model = trained_model()
    features = random_features(9)
    permutation = torch.from_numpy(np.random.default_rng(1).permutation(9))
    with torch.no_grad():
        logits = model(features)
        permuted = model(features[:, :, permutation])
    assert not torch.allclose(logits, logits[:, :, permutation])  # the test can tell
    torch.testing.assert_close(permuted, logits[:, :, permutation], atol=1e-5, rtol=1e-5)


def test_step_by_step_equals_the_whole_episode_and_is_causal():
    model = trained_model()
    features = random_features(7, seed=2)
    with torch.no_grad():
        whole = model(features)
        state, steps = None, []
        for t in range(features.shape[1]):
            logits, state = model.step(features[:, t], state)
            steps.append(logits)
        changed = features.clone()
        changed[:, 10:] = torch.randn(
            changed[:, 10:].shape, generator=torch.Generator().manual_seed(0)
        )
        later = model(changed)
    torch.testing.assert_close(torch.stack(steps, dim=1), whole, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(later[:, :10], whole[:, :10])
    assert not torch.allclose(later[:, 10:], whole[:, 10:])


def test_an_untrained_belief_is_the_generators_prior():
    batch = belief_batch(np.random.default_rng(5), 16, 4, 10)
    config = BeliefTrainingConfig(updates=1)
    model = AmortisedBelief(config.width, config.heads, config.mix_layers)
    probability = synapse_probabilities(model, batch)  # [B, T, n]
    expected = np.broadcast_to(np.clip(batch.prior, 1e-4, 1)[:, None, :], probability.shape)
    expected = np.where(batch.is_target[:, None, :], 0.0, expected)
    np.testing.assert_allclose(probability, expected, atol=1e-6)
    neurons = np.arange(16)
    target = np.flatnonzero(batch.is_target[0])[0]
    distance_prior = connection_probability(np.abs(neurons - target))
    np.testing.assert_allclose(batch.prior[0][neurons != target], distance_prior[neurons != target])


def test_scores_of_the_base_rate_and_of_the_truth():
    batch = belief_batch(np.random.default_rng(6), 8, 5, 12)
    base = np.broadcast_to(batch.prior[:, None, :], (5, 12, 8))
    (row,) = belief_scores(base, batch, (12,))
    assert row["removed"] == pytest.approx(0.0, abs=1e-12)
    truth = np.broadcast_to((batch.labels > 0)[:, None, :], (5, 12, 8)).astype(float)
    (row,) = belief_scores(truth, batch, (1,))
    assert row["cross_entropy"] == pytest.approx(1e-6, rel=1e-3)  # the probability floor
    with pytest.raises(ValueError, match="after_steps must lie in 1..12"):
        belief_scores(truth, batch, (13,))


def test_the_behaviour_mix_never_stimulates_the_target():
    rng = np.random.default_rng(7)
    targets = rng.integers(0, 6, size=200)
    actions = BehaviourMix(min_rate=1.0, max_rate=1.0, stretch_probability=0.0).actions(
        rng, 6, targets, 30
    )
    assert (actions >= 0).all() and (actions != targets[:, None]).all()
    still = BehaviourMix(min_rate=0.0, max_rate=0.0).actions(rng, 6, targets, 30)
    assert (still == -1).all()
    with pytest.raises(ValueError, match="min_rate <= max_rate"):
        BehaviourMix(min_rate=0.6, max_rate=0.5)


def test_bad_histories_and_configs_are_named():
    with pytest.raises(BeliefShapeError, match=f"features must be \\[B, T, n, {N_FEATURES}\\]"):
        AmortisedBelief()(torch.zeros(1, 2, 3, 4))
    with pytest.raises(BeliefShapeError, match="actions must be"):
        belief_features(
            np.zeros((1, 4, 3)), np.zeros((1, 4, 3), bool), np.zeros((1, 5)), np.zeros(1)
        )
    with pytest.raises(BeliefShapeError, match="targets must be neuron indices"):
        belief_features(np.zeros((1, 4, 3)), np.zeros((1, 4, 3), bool),
                        np.zeros((1, 4), int), np.array([3]))  # fmt: skip
    with pytest.raises(ValueError, match="sizes must be integers >= 2"):
        BeliefTrainingConfig(sizes=(1,))
    with pytest.raises(ValueError, match="updates must be a positive integer"):
        BeliefTrainingConfig(updates=0)


_TRAINED: dict[str, AmortisedBelief] = {}


def trained_model() -> AmortisedBelief:
    """A few updates, so the head is no longer zero (the prior alone is equivariant
    trivially)."""
    if "model" not in _TRAINED:
        config = BeliefTrainingConfig(sizes=(5, 7), batch=2, episode_length=12, updates=4,
                                      width=16, heads=2, log_every=2)  # fmt: skip
        _TRAINED["model"] = train_belief(config)[0].eval()
    return _TRAINED["model"]


def test_training_is_a_seeded_function_of_its_config():
    config = BeliefTrainingConfig(sizes=(4, 6), batch=2, episode_length=10, updates=3,
                                  width=8, heads=2, log_every=1)  # fmt: skip
    torch_state, numpy_state = torch.get_rng_state(), np.random.get_state()[1].copy()  # noqa: NPY002
    model, rows = train_belief(config)
    again, rows_again = train_belief(config)
    other, rows_other = train_belief(BeliefTrainingConfig(**{**config.__dict__, "seed": 1}))
    assert torch.equal(torch.get_rng_state(), torch_state)  # no global RNG drawn
    assert np.array_equal(np.random.get_state()[1], numpy_state)  # noqa: NPY002
    assert [r["train_loss"] for r in rows] == [r["train_loss"] for r in rows_again]
    assert [r["train_loss"] for r in rows] != [r["train_loss"] for r in rows_other]
    assert [r["update"] for r in rows] == [1, 2, 3]
    for name, value in model.state_dict().items():
        assert torch.equal(value, again.state_dict()[name])
