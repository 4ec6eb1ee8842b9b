"""The planners choose exactly the actions they chose before their slow steps were made
cheaper (issue 24, part 4): every action of identify-and-plan and of the oracle planner
on a handful of generated contexts, against tests/data/planning_reference.npz.

The reference was recorded with the NumPy beam search (commit of this file) by running
this module: ``python tests/test_planning_reference.py`` (re-record only on purpose: a
change of any planner's decision is a change of its results in docs/baselines.md).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import spikectl
from spikectl.envs.registration import VARIANTS
from spikectl.neuron.extensions import Extensions
from spikectl.planning import (
    Composition,
    DecisionSettings,
    IdentifyAndPlan,
    QMDPSettings,
    plan_episode,
)

REFERENCE = Path(__file__).parent / "data" / "planning_reference.npz"
REALISTIC = Extensions.coerce(VARIANTS.entry("spikectl/NeuronControlRealistic-v0")["extensions"])


def _splits(n: int, extensions=None):
    return spikectl.make_splits(100, 100, n, seed=0, n_val=100, extensions=extensions)


def play(contexts, indices, extensions=None, composition=None, told=False) -> np.ndarray:
    """int8 [len(indices), N]: identify-and-plan's actions, one episode per context
    (``env.reset(seed=i, options={"context": i})``, as benchmarks/bench_identify_and_plan.py),
    playing ``composition`` (None: the paper's) told the environment's ``extensions``;
    ``told``: told each context's weights."""
    env = spikectl.NeuronControlEnv(contexts=contexts, extensions=extensions)
    rows = []
    for i in indices:
        told_weights = contexts[i].weights if told else None
        policy = IdentifyAndPlan(composition=composition, extensions=extensions,
                                 told_weights=told_weights)  # fmt: skip
        observation, info = env.reset(seed=int(i), options={"context": int(i)})
        actions, done = [], False
        while not done:
            action = policy.act(observation, info)
            actions.append(action)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        rows.append(actions)
    return np.array(rows, dtype=np.int8)


def _oracle(contexts, indices, width=256) -> np.ndarray:
    return np.array([plan_episode(contexts[int(i)], width=width)[0] for i in indices], np.int8)


def _decision(name: str, **settings) -> dict:
    return {"composition": Composition(name, decision=DecisionSettings(**settings))}


# name -> (what to run, n, extensions, contexts, settings); the "full_" cases are for
# recording and the manual check of the whole test split, the test runs the others (the
# research-only part's case, identify_n8_discrete, is lab/planners/tests').
CASES = {
    "identify_n8": ("identify", 8, None, range(12), {}),
    "identify_n32": ("identify", 32, None, range(2), {}),
    "identify_n8_gamble16": ("identify", 8, None, range(4),
                             _decision("gamble16", gamble=QMDPSettings(networks=16))),
    "identify_n8_to_the_end": ("identify", 8, None, range(3), _decision("to-end", horizon=None)),
    "identify_n8_width8": ("identify", 8, None, range(4), _decision("width8", width=8)),
    "identify_n8_hypotheses4": ("identify", 8, None, range(4),
                                _decision("hypotheses4", hypotheses=4)),
    "identify_n8_told": ("identify", 8, None, range(4), {"told": True}),
    # The paper's composition told the Realistic variant's measurement noise (2 mV).
    "identify_realistic": ("identify", 8, REALISTIC, range(4), {}),
    "oracle_n8": ("oracle", 8, None, range(4), {}),
    "oracle_n32": ("oracle", 32, None, range(1), {"width": 64}),
    "oracle_realistic": ("oracle", 8, REALISTIC, range(3), {}),
}
FULL_CASES = {"full_identify_n8_test": ("identify", 8, None, range(100), {})}


def run_case(case) -> np.ndarray:
    kind, n, extensions, indices, settings = case
    test = _splits(n, extensions)[1]
    if kind == "oracle":
        return _oracle(test, indices, **settings)
    return play(test, indices, extensions, **settings)


@pytest.mark.parametrize("name", list(CASES))
def test_planners_choose_the_recorded_actions(name):
    expected = np.load(REFERENCE)[name]
    np.testing.assert_array_equal(run_case(CASES[name]), expected)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--check-full":
        # The whole test split against the recording (about a minute).
        for name, case in FULL_CASES.items():
            np.testing.assert_array_equal(run_case(case), np.load(REFERENCE)[name])
            print(name, "equal")
        sys.exit(0)
    recorded = {name: run_case(case) for name, case in {**CASES, **FULL_CASES}.items()}
    kept = dict(np.load(REFERENCE))  # the lab's cases stay as recorded
    np.savez_compressed(REFERENCE, **{**kept, **recorded})
    print({name: value.shape for name, value in recorded.items()})
