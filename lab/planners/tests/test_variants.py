"""The research-only parts of identify-and-plan (lab/planners): each plays exactly what
the core's switch it replaced played (the recorded actions of
tests/data/planning_reference.npz), legally, and differs from the core where it should."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from lab.planners import PlanUnderRelease, ReleaseChanceEvidence
from spikectl import Extensions, make_splits
from spikectl.envs.controller import batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.planning import (
    Composition,
    EstimatorSettings,
    IdentifyAndPlan,
    ObservationSettings,
    named_composition,
)

TESTS = Path(__file__).resolve().parents[3] / "tests"


def _core_test_module(name: str):
    """A module of the core's tests, loaded from its file under a name of its own: the
    lab's tier has a conftest of its own, so ``import conftest`` would find that one."""
    spec = importlib.util.spec_from_file_location(f"core_tests_{name}", TESTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


_core_conftest = _core_test_module("conftest")
play_by_hand, play_legally = _core_conftest.play_by_hand, _core_conftest.play_legally
_reference = _core_test_module("test_planning_reference")
REFERENCE, play = _reference.REFERENCE, _reference.play

pytestmark = pytest.mark.lab  # the lab's tier (pyproject.toml's markers)

DISCRETE = Composition("discrete", EstimatorSettings("discrete"))


def test_the_discrete_estimator_chooses_the_recorded_actions():
    test = make_splits(100, 100, 8, seed=0, n_val=100)[1]
    np.testing.assert_array_equal(play(test, range(4), composition=DISCRETE),
                                  np.load(REFERENCE)["identify_n8_discrete"])  # fmt: skip


def test_the_discrete_estimate_knows_more_and_is_rarely_wrong():
    # The discrete posterior is calibrated, not certain: an excitatory and an
    # inhibitory synapse onto one neuron from two neurons that always release together
    # look like no synapses, which the prior prefers (train[6] has one such pair).
    train = make_splits(100, 100, 8, seed=0)[0]
    known_counts, wrong = {}, 0
    for composition in (Composition(), DISCRETE):
        policy = batched(IdentifyAndPlan(composition=composition))
        evaluate_policy(train[:10], policy)
        known_counts[composition.name] = 0
        for context, copy in zip(train[:10], policy.copies, strict=True):
            signs, known = copy.estimate.weights(copy.known_sd)
            known_counts[composition.name] += known.sum()
            if composition is DISCRETE:
                wrong += (signs[known] != context.weights[known]).sum()
    assert known_counts["discrete"] > known_counts["paper"]
    assert wrong <= 0.01 * known_counts["discrete"]


def test_the_plan_under_release_does_not_stimulate_an_unrested_input():
    """As tests/test_planning_release.py's case: the core stimulates neuron 0 at step 2
    (an unrested input of the target), the lab's part follows the plan."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = 1
    pattern = np.zeros(60, dtype=np.int8)
    pattern[[1, 3]] = 1
    stochastic = Extensions(stochastic_release=True)
    named = named_composition(stochastic, 3)
    for decision, chosen in ((named.decision, 0), (PlanUnderRelease(), -1)):
        composition = named.but("plan-under-release", decision=decision)
        policy = IdentifyAndPlan(composition=composition, extensions=stochastic,
                                 told_weights=weights)  # fmt: skip
        actions, _ = play_by_hand(policy, weights, 2, pattern, [0, -1], steps=3)
        assert actions[-1] == chosen


def test_release_chance_evidence_never_settles_a_release():
    stochastic = Extensions(stochastic_release=True)
    observation = ReleaseChanceEvidence(task_model=True).bind(IdentifyAndPlan().params, stochastic)
    assert observation.stochastic_release and not observation.settles
    assert ObservationSettings(task_model=True).bind(IdentifyAndPlan().params, stochastic).settles


def test_the_recording_controller_plays_as_the_core_and_records_what_it_knows():
    """The research record's diagnostic (lab/planners/recording.py) acts exactly as the
    controller it wraps and records one row at each checked step of each episode: what
    its estimate calls known only grows, and at the end of a noiseless episode every
    weight it calls known is the network's."""
    from lab.planners.recording import RecordingIdentifyAndPlan

    _, contexts = make_splits(1, 3, 6, seed=5)
    record: list = []
    played = evaluate_policy(contexts, RecordingIdentifyAndPlan(contexts, record), seed=0)
    core = evaluate_policy(contexts, IdentifyAndPlan(), seed=0)
    np.testing.assert_array_equal(played.actions, core.actions)
    rows = np.array(record)
    assert rows.shape == (3 * len(RecordingIdentifyAndPlan.checked_steps), 3)
    by_step = rows.reshape(3, 3, 3)  # [step, episode, field]: the batch steps together
    assert list(by_step[:, 0, 0]) == list(RecordingIdentifyAndPlan.checked_steps)
    assert np.all(np.diff(by_step[:, :, 1], axis=0) >= 0) and np.all(by_step[-1, :, 1] > 0)
    assert np.all(rows[:, 2] == 1.0)
