"""Identify-and-plan's real-time form (``target_paths_only``, the ``-realtime``
compositions, the registered ``identify-and-plan-realtime``): which stimulations its beam
expands, that the pruning costs no planned reward."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import spike_pattern

from spikectl import NeuronParams, make_context
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.simulator import SimulatorState
from spikectl.planning import (
    DecisionSettings,
    beam_search,
    composition_name,
    model_of_context,
    named_composition,
)
from spikectl.planning.deciding import Situation, target_ancestors
from spikectl.planning.named import KNOWN_SD_FAST_LARGE, composition


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
    weights[0, 1] = 1  # 0 -> 1 (the target); 2 -> 3 cannot reach it
    weights[2, 3] = 1
    mask = np.array([True, True, False, True, True])  # 1 is not stimulable
    situation = Situation(0, 1, spike_pattern(10, [2]), mask)
    full = DecisionSettings().planning_model(Policy, weights, situation)
    pruned = DecisionSettings(target_paths_only=True).planning_model(Policy, weights, situation)
    assert full.actions.tolist() == [-1, 0, 2, 3]
    assert pruned.actions.tolist() == [-1, 0]
    assert np.array_equal(pruned.weights, full.weights)


def test_an_exhaustive_pruned_search_finds_the_full_searchs_return():
    # 0 -> 1 (the target) and 3 -> 1, beside 2 -> 4 that cannot reach it: with a beam
    # wide enough to keep every distinct state, both searches find the best return.
    weights = np.zeros((5, 5), dtype=int)
    weights[0, 1] = weights[3, 1] = weights[2, 4] = 1
    context = make_context(weights, target=1, pattern=spike_pattern(14, [1, 3, 7, 9, 13]))
    model = model_of_context(context)
    start = SimulatorState.at_rest(1, 5, model.params)
    full = beam_search(model, start, context.pattern, 0, 4096)
    keep = target_ancestors(model.weights[0], 1)[np.maximum(model.actions, 0)]
    pruned_model = replace(model, actions=model.actions[(model.actions == -1) | keep])
    pruned = beam_search(pruned_model, start, context.pattern, 0, 4096)
    assert pruned.rewards.sum() == pytest.approx(full.rewards.sum(), abs=1e-12)
    assert set(pruned.actions.tolist()) <= {-1, 0, 3}
    assert pruned.rewards.sum() == pytest.approx(1.0, abs=1e-12)  # every wanted spike hit


def test_where_every_neuron_reaches_the_target_the_plans_are_the_same(splits):
    for context in splits[0][:3]:
        model = model_of_context(context)
        weights = model.weights[0].copy()
        weights[:, context.target] = 1  # every neuron a direct input
        weights[context.target, context.target] = 0
        dense = replace(model, weights=weights[None])
        start = SimulatorState.at_rest(1, context.n_neurons, model.params)
        assert target_ancestors(weights, context.target).all()
        full = beam_search(dense, start, context.pattern, 0, 16, 20)
        keep = target_ancestors(weights, context.target)[np.maximum(dense.actions, 0)]
        pruned = beam_search(replace(dense, actions=dense.actions[(dense.actions == -1) | keep]),
                             start, context.pattern, 0, 16, 20)  # fmt: skip
        assert np.array_equal(full.actions, pruned.actions)
        assert np.array_equal(full.rewards, pruned.rewards)


@pytest.mark.parametrize(
    ("extensions", "n", "name"),
    [
        (None, 8, "paper-realtime"),
        (None, 16, "paper-16-realtime"),
        (None, 64, "paper-16-realtime"),
        (Extensions(observation_noise_mV=2.0), 8, "noise-realtime"),
        (Extensions(actuator="chr2"), 8, "paper-realtime"),  # as the fast form: the paper's
        (Extensions(hidden_fraction=0.25), 32, "hidden-16-realtime"),
    ],
)
def test_the_realtime_form_is_the_fast_form_with_target_paths_only(extensions, n, name):
    assert composition_name(extensions, n, realtime=True) == name
    realtime = named_composition(extensions, n, realtime=True)
    fast = named_composition(extensions, n, fast=True)
    assert realtime.decision == replace(fast.decision, target_paths_only=True)
    assert realtime.estimator == fast.estimator and realtime.observation == fast.observation
    assert realtime.prober == fast.prober


def test_the_declared_realtime_compositions():
    large = composition("paper-16-realtime")
    assert large.estimator.known_sd == KNOWN_SD_FAST_LARGE and large.decision.gamble is None
    assert large.decision.target_paths_only and not composition("paper-16-fast").decision \
        .target_paths_only  # fmt: skip
    assert composition("hidden-realtime").estimator.kind == "relays"


@pytest.mark.parametrize("bad", ["yes", 1, None])
def test_target_paths_only_must_be_a_bool(bad):
    with pytest.raises(TypeError, match="target_paths_only must be a bool"):
        DecisionSettings(target_paths_only=bad)
