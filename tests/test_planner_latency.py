"""Identify-and-plan under loop latency (issue 60, item 4; docs/extensions.md, "Loop
latency"): it reads each step's evidence with the action that landed then, plans from the
state its action will meet, and reads the latency from the observation."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from spikectl.envs.controller import ControllerInputError, DoNothing
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance
from spikectl.planning.in_flight import InFlight, latency_of, state_after
from spikectl.planning.oracle import OraclePlanner
from spikectl.planning.policy import IdentifyAndPlan

PARAMS = NeuronParams()
SUITE = Path(__file__).resolve().parents[1] / "docs" / "results" / "suite"


@pytest.fixture(scope="module")
def test_set():
    return load_split("paper", "test")


def _episode(env: NeuronControlEnv, policy, context: int) -> list[tuple[dict, dict]]:
    """One episode of ``policy`` on ``context``: every (observation, info) it was shown."""
    observation, info = env.reset(seed=0, options={"context": context})
    policy.reset()
    shown = []
    while True:
        shown.append((observation, info))
        observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
        if terminated or truncated:
            return shown


def _replayed(policy, shown: list[tuple[dict, dict]]) -> None:
    policy.reset()
    for observation, info in shown:
        policy.act(observation, info)


def _as_landed(shown: list[tuple[dict, dict]]) -> list[tuple[dict, dict]]:
    """The same observations as a loop without latency would show them: no actions in
    flight, and ``last_action`` the action that landed at the step before."""
    landed = [DO_NOTHING] + [int(observation[IN_FLIGHT_KEY][0]) for observation, _ in shown]
    rewritten = []
    for (observation, info), last in zip(shown, landed, strict=False):
        observation = {key: value for key, value in observation.items() if key != IN_FLIGHT_KEY}
        rewritten.append(({**observation, "last_action": last}, info))
    return rewritten


@pytest.mark.parametrize("latency", [1, 2])
def test_the_identification_reads_the_actions_that_landed(test_set, latency):
    """After an episode under latency L the estimate equals that of a controller without
    latency fed the same potentials with the landed stimulations as ``last_action``; fed
    the chosen ones instead (what it read before), the estimate differs."""
    env = NeuronControlEnv(contexts=test_set[:3], extensions={"latency_steps": latency})
    for context in range(3):
        policy = IdentifyAndPlan(PARAMS)
        shown = _episode(env, policy, context)
        assert any(int(o["last_action"]) != DO_NOTHING for o, _ in shown)
        landed = IdentifyAndPlan(PARAMS)
        _replayed(landed, _as_landed(shown))
        for mine, theirs in zip(policy.estimate.posterior(), landed.estimate.posterior(),
                                strict=True):  # fmt: skip
            np.testing.assert_array_equal(mine, theirs)
        chosen = IdentifyAndPlan(PARAMS)
        _replayed(chosen, [({k: v for k, v in o.items() if k != IN_FLIGHT_KEY}, i)
                           for o, i in shown])  # fmt: skip
        assert not np.array_equal(policy.estimate.posterior()[0],
                                  chosen.estimate.posterior()[0])  # fmt: skip


def test_without_latency_the_returns_are_the_committed_ones(test_set):
    """L = 0 (no actions in flight in the observation): the first networks' returns equal
    the suite's committed identify-and-plan returns (the whole replay is in the slow tier,
    tests/test_named_compositions.py)."""
    from spikectl.experiments import suite

    count = 10
    returns = evaluate_policy(test_set[:count], IdentifyAndPlan(test_set.params),
                              seed=suite.suite_version(1).env_seed).returns  # fmt: skip
    with open(SUITE / "identify-and-plan-per-network.csv", newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if row["task"] == "paper"]
    rows = sorted(rows, key=lambda row: int(row["context"]))[:count]
    assert [repr(float(value)) for value in returns] == [row["return"] for row in rows]


@pytest.mark.parametrize(("latency", "bar"), [(1, 0.78), (2, 0.78)])
def test_identify_and_plan_holds_under_latency(test_set, latency, bar):
    """On 20 test networks the controller, reading L from the observation, stays far above
    doing nothing (0.5; before it read latency: 0.46-0.48 on the 100), and told the weights
    it plans as well as the latency-aware oracle (within its narrower beam)."""
    contexts, extensions = test_set[:20], Extensions(latency_steps=latency)
    returns = evaluate_policy(contexts, IdentifyAndPlan(contexts.params, extensions=extensions),
                              extensions=extensions, seed=0).returns  # fmt: skip
    assert returns.mean() >= bar
    oracle = evaluate_policy(contexts, OraclePlanner(contexts, contexts.params),
                             extensions=extensions, seed=0).returns  # fmt: skip
    told = [
        evaluate_policy(contexts[i : i + 1], IdentifyAndPlan(
            contexts.params, extensions=extensions, told_weights=contexts[i].weights),
            extensions=extensions, seed=0).returns[0]
        for i in range(len(contexts))
    ]  # fmt: skip
    assert np.mean(told) >= oracle.mean() - 0.01
    nothing = evaluate_policy(contexts, DoNothing(), extensions=extensions, seed=0).returns
    assert nothing == pytest.approx(np.full(len(contexts), 0.5))


def test_the_latency_is_read_from_the_observation():
    assert latency_of({"voltage": np.zeros(3)}) == 0
    assert latency_of({IN_FLIGHT_KEY: np.array([-1, 2])}) == 2
    for bad in (np.zeros((1, 2), dtype=np.int64), np.zeros(0, dtype=np.int64),
                np.zeros(6, dtype=np.int64)):  # fmt: skip
        with pytest.raises(ControllerInputError, match=IN_FLIGHT_KEY):
            latency_of({IN_FLIGHT_KEY: bad})


def test_the_landed_action_is_the_first_in_flight_of_the_observation_before():
    """Chosen 3, 0, -1 at steps 0, 1, 2 under L = 2: 3 lands at step 2 and shows in the
    observation at step 3, whose ``last_action`` is -1."""
    flight = InFlight(2, 4)
    flight.read({IN_FLIGHT_KEY: np.array([-1, -1])})
    assert flight.landed({IN_FLIGHT_KEY: np.array([-1, 3]), "last_action": 3}) == -1
    assert flight.landing_now == -1
    assert flight.landed({IN_FLIGHT_KEY: np.array([3, 0]), "last_action": 0}) == -1
    assert flight.landing_now == 3
    assert flight.landed({IN_FLIGHT_KEY: np.array([0, -1]), "last_action": -1}) == 3
    assert flight.landing_now == 0
    assert InFlight(0, 4).landed({"last_action": 2}) == 2 and InFlight(0, 4).landing_now is None
    with pytest.raises(ControllerInputError, match="latency changed"):
        flight.landed({IN_FLIGHT_KEY: np.array([0])})
    with pytest.raises(ControllerInputError, match="-1..3"):
        flight.landed({IN_FLIGHT_KEY: np.array([0, 4])})


def test_the_state_met_is_the_model_stepped_through_the_actions_in_flight():
    """Neuron 0 excites neuron 1: stimulating 0 (in flight) makes it spike at the first
    step and 1 at the second, as the simulator steps them; the state given is untouched."""
    weights = np.array([[0.0, 1.0], [0.0, 0.0]])
    start = SimulatorState.at_rest(1, 2, PARAMS)
    met = state_after(start, weights, np.array([0, DO_NOTHING]), PARAMS)
    expected = start.copy()
    spikes = np.empty((1, 2, 2), dtype=bool)
    advance(expected, weights[None], np.array([[0, DO_NOTHING]]), PARAMS,
            np.empty((1, 2, 2)), spikes)  # fmt: skip
    assert spikes[0, 0].tolist() == [True, False] and spikes[0, 1].tolist() == [False, True]
    for field in ("voltage_mV", "refractory_left", "steps_since_release", "released"):
        np.testing.assert_array_equal(getattr(met, field), getattr(expected, field))
    assert (start.voltage_mV == PARAMS.v_rest_mV).all()
    unchanged = state_after(start, weights, np.zeros(0, dtype=np.int64), PARAMS)
    assert unchanged is not start and np.array_equal(unchanged.voltage_mV, start.voltage_mV)


def test_actions_chosen_too_late_to_land_are_do_nothing(test_set):
    """The last L actions never land; the controller does nothing there."""
    env = NeuronControlEnv(contexts=test_set[:2], extensions={"latency_steps": 2})
    policy = IdentifyAndPlan(PARAMS)
    shown = _episode(env, policy, 1)
    _replayed(policy, shown[:-2])
    assert [policy.act(o, i) for o, i in shown[-2:]] == [DO_NOTHING, DO_NOTHING]
