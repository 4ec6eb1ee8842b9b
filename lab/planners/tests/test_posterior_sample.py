"""Thompson sampling on identify-and-plan (lab/planners/variants.py's PosteriorSample):
each re-plan plans on the posterior's draw of its own index, and the plug-in replays its
record's returns (docs/results/iap-spikes)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from lab.planners import PosteriorSample
from spikectl import NeuronParams
from spikectl.planning.deciding import Situation

RECORD = Path(__file__).resolve().parents[3] / "docs" / "results" / "iap-spikes"


class _Estimate:
    """What planning_model reads of an estimate: draws column j of network k from
    connection_uniforms[k, 0, j] (here: the sign of the uniform minus a half)."""

    def sample(self, known_sd, connection_uniforms, sign_uniforms):
        return np.sign(connection_uniforms[:, :1, :] - 0.5).repeat(3, axis=1).astype(np.int8)


class _Policy:
    params = NeuronParams()
    known_sd = 0.25
    estimate = _Estimate()
    replans = 0
    uniforms = (np.random.default_rng(0).random((4, 3, 3)), np.zeros((4, 3)))

    @staticmethod
    def planned_neurons():
        return None


def test_each_replan_plans_on_its_own_draw():
    decision = PosteriorSample(samples=4)
    assert decision.draws == 4
    situation = Situation(0, 1, np.zeros(10, dtype=bool), np.ones(4, dtype=bool))
    policy = _Policy()
    drawn = []
    for replans in range(5):
        policy.replans = replans
        model = decision.planning_model(policy, np.zeros((3, 3)), situation)
        k = replans % 4
        expected = np.sign(policy.uniforms[0][k, 0] - 0.5)
        assert model.weights.shape == (1, 3, 3)
        np.testing.assert_array_equal(model.weights[0], np.tile(expected, (3, 1)))
        drawn.append(model.weights[0].copy())
    np.testing.assert_array_equal(drawn[4], drawn[0])  # the draws cycle
    assert any(not np.array_equal(drawn[0], other) for other in drawn[1:4])


def test_samples_must_be_a_positive_integer():
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="samples must be an integer >= 1"):
            PosteriorSample(samples=bad)


def test_the_record_replays():
    """variants.py's ``posterior-sample`` on the first validation networks, as the screen
    played them (the returns it wrote, six decimals)."""
    from lab.planners.screen import play, subset
    from lab.scripts import load_script

    count = 8
    variants = load_script("iap-spikes", "variants").variants()
    returns, _ = play("spikes-only", subset("spikes-only", range(count)),
                      variants["posterior-sample"])  # fmt: skip
    with open(RECORD / "screen200.csv", newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if row["variant"] == "posterior-sample"]
    committed = [row["return"] for row in sorted(rows, key=lambda row: int(row["context"]))]
    assert [f"{value:.6f}" for value in returns] == committed[:count]
