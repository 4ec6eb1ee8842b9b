"""The research record's diagnostic scripts stand in for parts of the planner (its
estimate, the weights it is told). Told nothing, each must play exactly the controller
it diagnoses: a library change their stand-ins do not follow fails here, not silently
in a committed table."""

from __future__ import annotations

import runpy
from pathlib import Path

import numpy as np
import pytest

from spikectl import IdentifyAndPlan, make_splits
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results"


def script(*parts: str) -> dict:
    """The script's module namespace (its ``main`` is not run)."""
    return runpy.run_path(str(RESULTS.joinpath(*parts)), run_name="research_script")


@pytest.fixture(scope="module")
def validation8():
    return make_splits(100, 100, 8, seed=0, n_val=100)[2][:12]


def test_diagnose_identify_told_nothing_is_identify_and_plan(validation8):
    diagnose = script("baselines", "diagnose_identify.py")
    named = evaluate_policy(validation8, IdentifyAndPlan()).returns
    with diagnose["_patched_policy"](validation8):
        patched = evaluate_policy(validation8, IdentifyAndPlan()).returns
    np.testing.assert_array_equal(patched, named)


def test_diagnose_identify_told_the_weights_is_the_known_weights_loop(validation8):
    diagnose = script("baselines", "diagnose_identify.py")
    with diagnose["_told_the_weights"](validation8):
        told = evaluate_policy(validation8, IdentifyAndPlan()).returns
    alone = [evaluate_policy(validation8[i : i + 1],
                             IdentifyAndPlan(known_weights=validation8[i].weights)).returns[0]
             for i in range(len(validation8))]  # fmt: skip
    np.testing.assert_array_equal(told, alone)
    assert told.mean() > evaluate_policy(validation8, IdentifyAndPlan()).returns.mean()


def test_diagnose_identify_told_the_column_from_step_0_is_told_it(validation8):
    """Told the target's column from the start, the loop plans on it: on these
    networks it scores at least what identify-and-plan does, network by network where
    the named loop missed a spike it could have had at step 1 or later."""
    diagnose = script("baselines", "diagnose_identify.py")
    named = evaluate_policy(validation8, IdentifyAndPlan()).returns
    with diagnose["_patched_policy"](validation8, told_from=0):
        told = evaluate_policy(validation8, IdentifyAndPlan()).returns
    assert told.mean() > named.mean() + 0.03


@pytest.mark.parametrize("task", ["stochastic", "hidden25"])
def test_reachable_told_nothing_is_the_named_controller(task):
    """``reachable.py``'s ``Told`` wraps the estimate; never told, it must learn as the
    named controller does (on ``stochastic``: releases settled from the residuals)."""
    reachable = script("reachable", "reachable.py")
    settings = reachable["settings"](task)
    contexts = suite.load_split(task, "validation")
    named, _ = suite.play(task, "validation", IdentifyAndPlan(**settings))
    never, _ = suite.play(task, "validation", reachable["Told"](contexts, 10**9, **settings))
    np.testing.assert_array_equal(never, named)
