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


def test_diagnose_identify_told_the_column_from_step_0_scores_higher(validation8):
    diagnose = script("baselines", "diagnose_identify.py")
    named = evaluate_policy(validation8, IdentifyAndPlan()).returns
    with diagnose["_patched_policy"](validation8, told_from=0):
        told = evaluate_policy(validation8, IdentifyAndPlan()).returns
    assert told.mean() > named.mean() + 0.03


class _PlansOn(IdentifyAndPlan):
    """Records, at each step, the target's column of the weights the policy planned on."""

    def __init__(self) -> None:
        super().__init__()
        self.columns: list[tuple[int, int, np.ndarray]] = []

    def spawn(self, index: int) -> IdentifyAndPlan:
        return self  # one sub-environment

    def act(self, observation, info) -> int:
        action = super().act(observation, info)
        target = int(observation["target"])
        self.columns.append((int(observation["step"]), target,
                             self._planned_weights[:, target].copy()))  # fmt: skip
        return action


def test_diagnose_identify_told_the_column_from_step_k_plans_on_it_from_step_k(validation8):
    """From the step it is told on, the loop plans on the true column at every step,
    also where no release changed the estimate that step (its planning weights are
    cached against the estimate's version)."""
    diagnose = script("baselines", "diagnose_identify.py")
    told_from, steps_checked = 5, 0
    for i in range(len(validation8)):
        one = validation8[i : i + 1]
        policy = _PlansOn()
        with diagnose["_patched_policy"](one, told_from=told_from):
            evaluate_policy(one, policy)
        truth = one[0].weights
        for step, target, column in policy.columns:
            if step >= told_from:
                np.testing.assert_array_equal(column, truth[:, target], err_msg=f"step {step}")
                steps_checked += 1
    assert steps_checked == len(validation8) * (60 - told_from)


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
