"""The told diagnostics (lab/planners/told.py): ToldColumns starts its spike likelihood
at the true columns, all of them or the target's, and replays the iap-spikes record."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from lab.planners.told import ToldColumns
from spikectl import NeuronControlEnv, make_splits
from spikectl.planning import EstimatorSettings, ObservationSettings
from spikectl.planning.named import composition

RECORD = Path(__file__).resolve().parents[3] / "docs" / "results" / "iap-spikes"
SPIKES = {"sensing": "spikes"}
TOLD = composition("spikes-fast").but("told", estimator=EstimatorSettings("spike-likelihood"),
                                      observation=ObservationSettings(task_model=True))


@pytest.mark.parametrize("columns", ["all", "target", "others"])
def test_told_columns_start_at_the_truth(columns):
    contexts = make_splits(2, 1, n_neurons=6, seed=3)[1]
    env = NeuronControlEnv(contexts=contexts, extensions=SPIKES)
    controller = ToldColumns(contexts, columns, composition=TOLD, extensions=env.extensions)
    observation, info = env.reset(seed=0, options={"context": 0})
    controller.act(observation, info)
    truth = np.sign(contexts[0].weights).astype(np.int8)
    target = int(observation["target"])
    signs, known = controller.estimate.weights(0.25)
    told = {"all": range(6), "target": [target],
            "others": [j for j in range(6) if j != target]}[columns]
    for j in told:
        np.testing.assert_array_equal(signs[:, j], truth[:, j])
        assert known[:, j].all() and controller.estimate.alive[j].sum() == 1
    if columns == "target":
        assert (controller.estimate.alive.sum(axis=1) > 1).sum() == 5
    if columns == "others":
        assert controller.estimate.alive[target].sum() > 1


def test_told_columns_refuses_other_columns():
    with pytest.raises(ValueError, match="columns must be 'all', 'target' or 'others'"):
        ToldColumns(None, "some", composition=TOLD)


def test_the_iap_spikes_diagnosis_replays():
    """diagnose.py's told runs on the first validation networks, as the record wrote them."""
    from lab.planners.screen import subset
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments import suite

    count = 6
    contexts = subset("spikes-only", range(count))
    extensions = suite.task("spikes-only", 2).extensions
    with open(RECORD / "diagnose-per-network.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    for columns in ("all", "target"):
        controller = ToldColumns(contexts, columns, composition=TOLD, extensions=extensions)
        returns = evaluate_policy(contexts, controller, extensions=extensions,
                                  seed=suite.suite_version(2).env_seed).returns  # fmt: skip
        name = "told-all-columns" if columns == "all" else "told-target-column"
        committed = [row["return"] for row in rows if row["variant"] == name][:count]
        assert [f"{value:.6f}" for value in returns] == committed
