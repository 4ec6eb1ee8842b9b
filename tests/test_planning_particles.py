"""The discrete posterior on the touched entries (spikectl.planning.particles): equal to
the exact enumeration while nothing is pruned, hand-computed on 3 neurons, bounded and
right where it is sure at 16 and 32 neurons."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spikectl.contexts import make_splits
from spikectl.contexts.generation import EXCITATORY_PROBABILITY, connection_probability
from spikectl.envs.controller import batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.planning import (
    Composition,
    ConnectivityEstimate,
    DecisionSettings,
    EstimatorSettings,
    IdentifyAndPlan,
)
from spikectl.planning.discrete import (
    _OUTLIER_RANGE,
    OUTLIER_PROBABILITY,
    DiscreteConnectivityEstimate,
)
from spikectl.planning.particles import ParticleConnectivityEstimate


def random_evidence(weights: np.ndarray, steps: int, rate: float, seed: int):
    """``steps`` (released, residual, observed) triples on ``weights`` [n, n]: random
    releases at ``rate``, the residuals they cause plus a little noise, most columns
    observed."""
    rng = np.random.default_rng(seed)
    n = weights.shape[0]
    evidence = []
    for _ in range(steps):
        released = (rng.random(n) < rate).astype(float)
        residual = released @ weights + rng.normal(0.0, 0.05, n)
        evidence.append((released, residual, rng.random(n) < 0.9))
    return evidence


def dense_network(n: int, seed: int) -> np.ndarray:
    """[n, n] in {-1, 0, +1}, Dale's law, connections with probability 0.4."""
    rng = np.random.default_rng(seed)
    weights = np.zeros((n, n), dtype=int)
    for pre in range(n):
        sign = 1 if rng.random() < 0.8 else -1
        weights[pre] = np.where(rng.random(n) < 0.4, sign, 0)
    np.fill_diagonal(weights, 0)
    return weights


def test_unpruned_particles_are_the_exact_posterior():
    weights = dense_network(6, seed=0)
    evidence = random_evidence(weights, 30, rate=0.3, seed=0)
    exact = DiscreteConnectivityEstimate(6, 0.1)
    particles = ParticleConnectivityEstimate(6, 0.1, max_hypotheses=10**6)
    for step in evidence:
        exact.add(*step)
        particles.add(*step)
        for ours, theirs in zip(particles.posterior(), exact.posterior(), strict=True):
            np.testing.assert_allclose(ours, theirs, atol=1e-7)  # (e^-40 dropped)
    # the evidence identifies this network; only touched entries were enumerated
    assert np.array_equal(np.rint(particles.posterior()[0]), weights)
    assert max(h.shape[0] for h in particles.hypotheses) < 3**5


def test_one_release_by_hand():
    # Neuron 0 releases; neuron 2's residual is 1 (w_in), neuron 1's is not observed.
    # Column 2's only touched entry is G[0, 2]: P(v) ∝ prior(v) (Gaussian + outlier
    # likelihood of 1 - v). That makes row 0 excitatory beyond 0.99 (Dale's law): its
    # value -1 is then all but ruled out, in column 2 and in the untouched G[0, 1].
    # G[1, 2] keeps its prior, and column 1 is untouched.
    sd, dale = 0.1, math.exp(-30.0)
    estimate = ParticleConnectivityEstimate(3, sd)
    estimate.add(np.array([1.0, 0.0, 0.0]), np.array([0.0, 5.0, 1.0]),
                 np.array([False, False, True]))  # fmt: skip
    far, near = connection_probability(np.array([2, 1]))
    excitatory = EXCITATORY_PROBABILITY

    def likelihood(value):
        gaussian = math.exp(-0.5 * ((1 - value) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
        return (1 - OUTLIER_PROBABILITY) * gaussian + OUTLIER_PROBABILITY / _OUTLIER_RANGE

    prior = {-1: far * (1 - excitatory) * dale, 0: 1 - far, 1: far * excitatory}
    joint = {v: prior[v] * likelihood(v) for v in (-1, 0, 1)}
    total = sum(joint.values())
    mean, sd_post = estimate.posterior()
    assert mean[0, 2] == pytest.approx((joint[1] - joint[-1]) / total, rel=1e-9)
    second = (joint[1] + joint[-1]) / total
    assert sd_post[0, 2] == pytest.approx(math.sqrt(second - mean[0, 2] ** 2), rel=1e-6)
    assert mean[1, 2] == pytest.approx(near * (2 * excitatory - 1), rel=1e-9)
    untouched = {-1: near * (1 - excitatory) * dale, 0: 1 - near, 1: near * excitatory}
    assert mean[0, 1] == pytest.approx(
        (untouched[1] - untouched[-1]) / sum(untouched.values()), rel=1e-9
    )
    assert estimate.touched.sum() == 1 and estimate.hypotheses[2].shape[0] == 3


def test_columns_keep_at_most_max_hypotheses_and_are_rarely_wrong_where_sure():
    # A generated 16-neuron network (the prior's own), a fifth of the neurons releasing
    # each step: 64 hypotheses per column at most, and the entries called known are
    # the network's but for a rare pruned or outvoted one.
    (context,), _ = make_splits(1, 1, n_neurons=16, seed=1)
    estimate = ParticleConnectivityEstimate(16, 0.1, max_hypotheses=64)
    for step in random_evidence(context.weights, 40, rate=0.2, seed=1):
        estimate.add(*step)
        assert max(h.shape[0] for h in estimate.hypotheses) <= 64
    signs, known = estimate.weights(known_sd=0.25)
    assert known.sum() > 200
    assert (signs[known] != context.weights[known]).sum() <= 0.01 * known.sum()


def test_samples_follow_the_hypotheses_the_prior_and_the_uniforms():
    estimate = ParticleConnectivityEstimate(4, 0.1)
    # 0 and 1 release together; column 3 sees +1: (G[0,3], G[1,3]) is (1, 0) or (0, 1)
    estimate.add(np.array([1.0, 1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]),
                 np.array([False, False, False, True]))  # fmt: skip
    k = 200
    rng = np.random.default_rng(0)
    connection, sign = rng.random((k, 4, 4)), rng.random((k, 4))
    drawn = estimate.sample(0.25, connection, sign)
    assert drawn.shape == (k, 4, 4) and drawn.dtype == np.int8
    assert (np.diagonal(drawn, axis1=1, axis2=2) == 0).all()
    pair = drawn[:, [0, 1], 3]
    assert set(map(tuple, pair)) <= {(1, 0), (0, 1), (1, 1), (0, 0), (1, -1), (-1, 1)}
    assert ((pair.sum(axis=1)) == 1).mean() > 0.95  # the hypotheses the residual allows
    # an untouched entry (G[2, 0]) is a connection where its uniform is below the prior's
    # probability, of the sign its row's uniform draws
    p = connection_probability(np.array([2]))[0]
    row_sign = np.where(sign[:, 2] < EXCITATORY_PROBABILITY, 1, -1)
    expected = np.where(connection[:, 2, 0] < p, row_sign, 0)
    assert np.array_equal(drawn[:, 2, 0], expected)
    # the same uniforms give the same draws
    assert np.array_equal(estimate.sample(0.25, connection, sign), drawn)


@pytest.mark.parametrize("n", [16, 32])
def test_on_the_same_evidence_particles_know_more_than_the_gaussian_estimate(n):
    # Ten steps of confounded evidence (three in ten neurons release together): integers
    # tell apart neurons that released together (a sum of 0 or 2) where the ridge
    # regression waits for one to release alone.
    (context,), _ = make_splits(1, 1, n_neurons=n, seed=2)
    gaussian, particles = ConnectivityEstimate(n, 0.1), ParticleConnectivityEstimate(n, 0.1)
    for step in random_evidence(context.weights, 10, rate=0.3, seed=2):
        gaussian.add(*step)
        particles.add(*step)
    known = {"gaussian": gaussian.weights(0.25)[1], "particles": particles.weights(0.25)[1]}
    assert known["particles"].sum() > 1.5 * known["gaussian"].sum()
    signs = particles.weights(0.25)[0]
    assert (signs[known["particles"]] != context.weights[known["particles"]]).sum() <= (
        0.02 * known["particles"].sum()
    )


def test_identify_and_plan_with_particles_at_16_and_32_neurons():
    # On generated networks the controller is legal (the rollout raises otherwise) and
    # deterministic, scores above doing nothing (0.5), and the entries it calls known are
    # the network's but for a rare one (at most 2 %; the Gaussian estimate errs too at 32).
    for n in (16, 32):
        train, _ = make_splits(3, 1, n_neurons=n, seed=3)
        particles = Composition("particles-width8", EstimatorSettings("particles"),
                                decision=DecisionSettings(width=8))  # fmt: skip
        policy, twin = (batched(IdentifyAndPlan(composition=particles)) for _ in range(2))
        result, again = evaluate_policy(train, policy), evaluate_policy(train, twin)
        assert np.array_equal(result.actions, again.actions)
        assert result.returns.mean() > 0.5
        known_count = wrong = 0
        for context, copy in zip(train, policy.copies, strict=True):
            signs, known = copy.estimate.weights(copy.known_sd)
            known_count += known.sum()
            wrong += (signs[known] != context.weights[known]).sum()
        assert known_count > 3 * n and wrong <= 0.02 * known_count


def test_particles_refuse_bad_settings():
    with pytest.raises(ValueError, match="residual_sd"):
        ParticleConnectivityEstimate(8, 0.0)
    with pytest.raises(ValueError, match="max_hypotheses"):
        ParticleConnectivityEstimate(8, 0.1, max_hypotheses=2)
