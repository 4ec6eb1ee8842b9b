"""Reliability round 4 (issue 40), what controllers are given (classes 6 and 11).

NaN voltages made both trained controllers answer "do nothing" silently, a pattern value
of 7.5 was accepted, a mask allowing nothing gave -1 from the PyTorch controller and an
error from the compiled one; ``act(None, info)``, ``RandomLegal(seed=-1)`` and a Witness
built on another set were tracebacks or silent. Each is now a ControllerInputError (a
ValueError) naming the controller and the entry, the same from every controller.
"""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.agents import make_agent
from spikectl.agents.compiled import CompiledPolicy
from spikectl.agents.greedy import GreedyController
from spikectl.contexts import make_splits
from spikectl.envs.controller import ControllerInputError, RandomLegal, Witness
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv


@pytest.fixture(scope="module")
def sets():
    return make_splits(4, 4, 5, 20, seed=1)


@pytest.fixture(scope="module")
def start(sets):
    env = NeuronControlEnv(contexts=sets[1])
    return env.reset(seed=0, options={"context": 1})


@pytest.fixture(scope="module")
def controllers(sets):
    from spikectl.training.loaders import load_controller

    network = make_agent("tdrqn", 5, 20)
    env = NeuronControlEnv(contexts=sets[1])
    return {"GreedyController": GreedyController(network),
            "CompiledPolicy": CompiledPolicy.from_network(network),
            "RandomLegal": RandomLegal(0),
            "IdentifyAndPlan": load_controller("identify-and-plan", env=env),
            "OraclePlanner": load_controller("oracle", env=env)}  # fmt: skip


def nonsense(observation, info):
    nan = {**observation, "voltage": np.full_like(observation["voltage"], np.nan)}
    inf = {**observation, "voltage": np.full_like(observation["voltage"], np.inf)}
    pattern = {**observation, "pattern": observation["pattern"] * 7.5}
    negative = {**observation, "pattern": -observation["pattern"]}
    return {
        "observation None": ((None, info), "must be dicts"),
        "info None": ((observation, None), "must be dicts"),
        "no voltage": (({k: v for k, v in observation.items() if k != "voltage"}, info),
                       "lacks"),  # fmt: skip
        "no action mask": ((observation, {}), "lacks"),
        "NaN voltages": ((nan, info), "NaN or infinite"),
        "infinite voltages": ((inf, info), "NaN or infinite"),
        "pattern 7.5": ((pattern, info), "other than 0 and 1"),
        "pattern -1": ((negative, info), "other than 0 and 1"),
        "mask of 2s": ((observation, {"action_mask": np.full(6, 2)}), "other than 0 and 1"),
        "mask allowing nothing": ((observation, {"action_mask": np.zeros(6, bool)}),
                                  "allows no action"),  # fmt: skip
        "voltage of text": (({**observation, "voltage": "high"}, info), "not numeric"),
    }


CASES = list(nonsense({"voltage": np.zeros(5), "pattern": np.zeros(20)}, {}))
MASK_CASES = ("observation None", "info None", "no action mask", "mask of 2s",
              "mask allowing nothing")  # fmt: skip
"""What the random controller, which reads the action mask only, is given wrong."""


@pytest.mark.parametrize(
    ("who", "case"),
    [(who, case) for who in ("GreedyController", "CompiledPolicy", "IdentifyAndPlan",
                             "OraclePlanner") for case in CASES]  # fmt: skip
    + [("RandomLegal", case) for case in MASK_CASES],
)
def test_nonsense_observations_are_one_named_error_from_every_controller(
    controllers, start, who, case
):
    (observation, info), message = nonsense(*start)[case]
    controller = controllers[who]
    controller.reset()
    with pytest.raises(ControllerInputError, match=rf"^{who}\.act: .*{message}"):
        controller.act(observation, info)
    controller.reset()
    assert -1 <= controller.act(*start) < 5  # the real observation still plays


def test_batched_nonsense_is_refused_too(sets):
    env = NeuronControlVectorEnv(num_envs=2, contexts=sets[1])
    observations, infos = env.reset(seed=0)
    greedy = GreedyController(make_agent("tdrqn", 5, 20))
    nan = {**observations, "voltage": observations["voltage"].copy()}
    nan["voltage"][1, 0] = np.nan
    with pytest.raises(ControllerInputError, match="NaN"):
        greedy.act_batch(nan, infos)
    mask = infos["action_mask"].copy()
    mask[0] = False
    with pytest.raises(ControllerInputError, match="allows no action"):
        greedy.act_batch(observations, {**infos, "action_mask": mask})
    assert greedy.act_batch(observations, infos).shape == (2,)


def test_seeds_and_witnesses_of_another_set_are_refused(sets, start):
    with pytest.raises(ValueError, match="seed must be a non-negative integer, got -1"):
        RandomLegal(seed=-1)
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        RandomLegal(seed=1.5)
    train, test = sets
    observation, info = start  # context 1 of the test set
    with pytest.raises(ControllerInputError, match="not those of its context in the Witness"):
        Witness(train).act(observation, info)
    with pytest.raises(ControllerInputError, match="outside its set of 4 contexts"):
        Witness(test).act(observation, {**info, "context_index": 7})
    assert Witness(test).act(observation, info) == test[1].agent_witness[0]
