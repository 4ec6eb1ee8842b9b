"""The beam cut to the target's ancestors (lab/planners/target_paths.py): which
stimulations it expands, that the cut costs no planned reward, and that it replays the
returns of its record (docs/results/realtime-iap)."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lab.planners import TargetPathsOnly, target_ancestors
from spikectl import NeuronParams, make_context, make_splits
from spikectl.neuron import SimulatorState
from spikectl.planning import DecisionSettings, beam_search, model_of_context
from spikectl.planning.deciding import Situation

RECORD = Path(__file__).resolve().parents[3] / "docs" / "results" / "realtime-iap"


def _pattern(length: int, spikes: list[int]) -> np.ndarray:
    pattern = np.zeros(length, dtype=bool)
    pattern[spikes] = True
    return pattern


def _pruned(model):
    """``model`` with its actions cut as TargetPathsOnly cuts them."""
    keep = target_ancestors(model.weights[0], model.target)[np.maximum(model.actions, 0)]
    return replace(model, actions=model.actions[(model.actions == -1) | keep])


def test_the_targets_ancestors_follow_the_synapses_back_to_it():
    # 2 -> 0 -> 1 -> 3 (the target), 4 -| 3, 3 -> 5 (downstream only), 6 alone.
    weights = np.zeros((7, 7))
    weights[2, 0] = weights[0, 1] = weights[1, 3] = 1.0
    weights[4, 3] = -1.0
    weights[3, 5] = 0.37  # a planned posterior mean counts as a synapse
    assert np.flatnonzero(target_ancestors(weights, 3)).tolist() == [0, 1, 2, 3, 4]
    assert np.flatnonzero(target_ancestors(weights, 5)).tolist() == [0, 1, 2, 3, 4, 5]
    assert np.flatnonzero(target_ancestors(weights, 6)).tolist() == [6]
    weights[5, 2] = 1.0  # a cycle through the target
    assert target_ancestors(weights, 3).sum() == 6 and not target_ancestors(weights, 3)[6]


def test_the_planning_model_expands_only_what_reaches_the_target():
    class Policy:  # what planning_model reads of the controller
        params = NeuronParams()

        @staticmethod
        def planned_neurons():
            return None

    weights = np.zeros((4, 4), dtype=np.int8)
    weights[0, 1] = weights[2, 3] = 1  # 0 -> 1 (the target); 2 -> 3 cannot reach it
    mask = np.array([True, True, False, True, True])  # 1 is not stimulable
    situation = Situation(0, 1, _pattern(10, [2]), mask)
    full = DecisionSettings().planning_model(Policy, weights, situation)
    pruned = TargetPathsOnly().planning_model(Policy, weights, situation)
    assert full.actions.tolist() == [-1, 0, 2, 3]
    assert pruned.actions.tolist() == [-1, 0]
    assert np.array_equal(pruned.weights, full.weights)


def test_an_exhaustive_pruned_search_finds_the_full_searchs_return():
    # 0 -> 1 (the target) and 3 -> 1, beside 2 -> 4 that cannot reach it: with a beam
    # wide enough to keep every distinct state, both find every wanted spike.
    weights = np.zeros((5, 5), dtype=int)
    weights[0, 1] = weights[3, 1] = weights[2, 4] = 1
    context = make_context(weights, target=1, pattern=_pattern(14, [1, 3, 7, 9, 13]))
    model = model_of_context(context)
    start = SimulatorState.at_rest(1, 5, model.params)
    full = beam_search(model, start, context.pattern, 0, 4096)
    pruned = beam_search(_pruned(model), start, context.pattern, 0, 4096)
    assert pruned.rewards.sum() == pytest.approx(full.rewards.sum(), abs=1e-12)
    assert pruned.rewards.sum() == pytest.approx(1.0, abs=1e-12)
    assert set(pruned.actions.tolist()) <= {-1, 0, 3}


def test_where_every_neuron_reaches_the_target_the_plans_are_the_same():
    for context in make_splits(3, 1, seed=5)[0]:
        model = model_of_context(context)
        weights = model.weights[0].copy()
        weights[:, context.target] = 1  # every neuron a direct input
        weights[context.target, context.target] = 0
        dense = replace(model, weights=weights[None])
        start = SimulatorState.at_rest(1, context.n_neurons, model.params)
        full = beam_search(dense, start, context.pattern, 0, 16, 20)
        pruned = beam_search(_pruned(dense), start, context.pattern, 0, 16, 20)
        assert np.array_equal(full.actions, pruned.actions)
        assert np.array_equal(full.rewards, pruned.rewards)


@pytest.mark.parametrize(("task", "count"), [("paper", 20), ("n16", 3)])
def test_the_record_replays(task, count):
    """measure.py's controller, network by network, as the record played it (the suite's
    protocol; these environments draw nothing, so a prefix replays)."""
    from lab.scripts import load_script
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments import suite

    measure = load_script("realtime-iap", "measure")
    contexts = suite.load_split(task, "test")[:count]
    extensions = suite.task(task).extensions
    controller = measure.controller("target-paths", contexts, extensions)
    assert isinstance(controller.composition.decision, TargetPathsOnly)
    returns = evaluate_policy(contexts, controller, extensions=extensions,
                              seed=suite.suite_version(1).env_seed).returns  # fmt: skip
    with open(RECORD / "test-per-network.csv", newline="") as handle:
        rows = [row for row in csv.DictReader(handle)
                if row["task"] == task and row["form"] == "target-paths"]  # fmt: skip
    committed = [row["return"] for row in sorted(rows, key=lambda row: int(row["context"]))]
    assert [repr(float(value)) for value in returns] == committed[:count]
