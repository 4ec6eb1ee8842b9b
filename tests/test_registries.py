"""The extension points, each used the public way: a controller, an environment variant,
a suite version and a task, each one module-level definition and one registry line, then
played through the normal entry point (``load_controller``, ``gymnasium.make``,
``spikectl benchmark``); unknown names are refused in one line naming the known ones."""

from __future__ import annotations

import csv
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from conftest import run_main

import spikectl
from spikectl.envs.controller import DoNothing
from spikectl.experiments import suite
from spikectl.experiments.suite import SuiteVersion, Task
from spikectl.registry import RegistryError
from spikectl.training.loaders import CONTROLLERS, Played
from spikectl.wrappers import FinalInfoEpisodeStatistics

VARIANT_ID = "spikectl-test/NeuronControlNoisy3-v0"
TEST_SUITE = 901
"""A version number no release uses: the test's own suite beside v1."""
SUITE = SuiteVersion(TEST_SUITE)
PAPER_SETS = suite.task("paper").checksums
"""An environment-level task on n = 8 with seed 0 plays the paper's networks."""


class FirstLegalNeuron:
    """Stimulates the lowest-numbered legal neuron every step (a test's controller)."""

    def reset(self) -> None:
        pass

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        return int(np.flatnonzero(info["action_mask"][1:])[0])


def first_legal_neuron(played: Played, seed: int) -> FirstLegalNeuron:
    return FirstLegalNeuron()


def register_plugins() -> None:
    """One registry line per plug-in (registering the same one again is a no-op)."""
    spikectl.register_controller("first-legal-neuron", first_legal_neuron,
                                 "stimulates the lowest-numbered legal neuron")  # fmt: skip
    spikectl.register_env_variant(VARIANT_ID, {"extensions": {"observation_noise_mV": 3.0}})
    spikectl.register_suite_version(SUITE)
    spikectl.register_task(Task("noise3", VARIANT_ID, {}, 8, 0, "measurement noise 3 mV",
                                PAPER_SETS), TEST_SUITE)  # fmt: skip


def test_a_registered_controller_is_loaded_by_name():
    register_plugins()
    env = gym.make("spikectl/NeuronControl-v0", contexts={"n_train": 4, "n_test": 4})
    controller = spikectl.load_controller("first-legal-neuron", env=env)
    assert isinstance(controller, FirstLegalNeuron)
    _, info = env.reset(seed=0, options={"context": 0})
    target = env.unwrapped.contexts[0].target
    assert controller.act({}, info) == (1 if target == 0 else 0)
    assert CONTROLLERS.entry("first-legal-neuron").description.startswith("stimulates")


def test_a_registered_controller_plays_the_benchmark(capsys, tmp_path):
    register_plugins()
    out = tmp_path / "scores.csv"
    code, stdout, _ = run_main(["benchmark", "first-legal-neuron", "--task", "paper",
                                "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, stdout
    with open(out, newline="") as file:
        (row,) = csv.DictReader(file)
    played = suite.score("paper", "test", lambda seed: FirstLegalNeuron())
    assert float(row["mean_return"]) == pytest.approx(played.mean_return, abs=1e-6)
    assert (row["suite_version"], row["controller"], row["seeds"]) == ("1", "first-legal-neuron",
                                                                       "1")  # fmt: skip
    assert played.mean_return != 0.5  # it acts: not doing nothing


def test_a_registered_variant_and_its_flat_twin_are_made_by_gymnasium():
    register_plugins()
    env = gym.make(VARIANT_ID, contexts={"n_train": 4, "n_test": 4})
    assert env.unwrapped.extensions.observation_noise_mV == 3.0
    flat = gym.make("spikectl-test/NeuronControlNoisy3Flat-v0", contexts={"n_train": 4,
                                                                          "n_test": 4})  # fmt: skip
    assert flat.unwrapped.env.extensions.observation_noise_mV == 3.0
    # ... and the flat twin's FinalInfo twin, wrapped for CleanRL's published scripts.
    twin = gym.make("spikectl-test/NeuronControlNoisy3FlatFinalInfo-v0",
                    contexts={"n_train": 4, "n_test": 4})  # fmt: skip
    assert isinstance(twin, FinalInfoEpisodeStatistics)
    assert twin.unwrapped.env.extensions.observation_noise_mV == 3.0
    envs = gym.make_vec(VARIANT_ID, num_envs=2, contexts={"n_train": 4, "n_test": 4})
    assert isinstance(envs, spikectl.NeuronControlVectorEnv)
    assert envs.extensions.observation_noise_mV == 3.0
    # Arguments given to make override the variant's, as for the library's variants.
    quiet = gym.make(VARIANT_ID, extensions={"observation_noise_mV": 0.5})
    assert quiet.unwrapped.extensions.observation_noise_mV == 0.5


def test_a_second_suite_version_is_listed_and_played_beside_a_frozen_v1(capsys, tmp_path):
    register_plugins()
    assert {"1", str(TEST_SUITE)} <= set(suite.SUITES)
    assert suite.suite_version(TEST_SUITE).names() == ("noise3",)
    assert suite.task("noise3", TEST_SUITE).extensions.observation_noise_mV == 3.0
    out = tmp_path / "scores.csv"
    code, stdout, _ = run_main(["benchmark", "do-nothing", "--suite", str(TEST_SUITE),
                                "--task", "all", "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, stdout
    assert f"benchmark suite v{TEST_SUITE}" in stdout
    with open(out, newline="") as file:
        (row,) = csv.DictReader(file)
    assert (row["suite_version"], row["task"]) == (str(TEST_SUITE), "noise3")
    assert (float(row["mean_return"]), float(row["normalised"])) == (0.5, 0.0)
    # The task's sets are the paper's networks, checked against its pinned checksums.
    assert suite.load_split("noise3", "test", TEST_SUITE) == suite.load_split("paper", "test")
    # v1 is untouched and refuses new tasks.
    v1 = suite.suite_version(1)
    assert len(v1.names()) == 10 and "noise3" not in v1.names()
    with pytest.raises(RegistryError, match="suite v1 is frozen"):
        spikectl.register_task(Task("noise3", VARIANT_ID, {}, 8, 0, "", PAPER_SETS), 1)


def test_a_task_without_its_checksums_is_refused():
    register_plugins()
    with pytest.raises(RegistryError, match="pins no checksum for validation, test"):
        spikectl.register_task(Task("bare", VARIANT_ID, {}, 8, 0, "", {"train": "0" * 64}),
                               TEST_SUITE)  # fmt: skip


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: CONTROLLERS.load("nope"),
         "unknown controller 'nope'; this spikectl has do-nothing, random, identify-and-plan, "
         "oracle, witness"),
        (lambda: spikectl.load_controller("nope"),
         "no controller 'nope': not a run directory, not a compiled policy file, and not one of "
         "do-nothing, random, identify-and-plan, oracle, witness"),
        (lambda: suite.suite_version(7),
         "unknown benchmark suite version '7'; this spikectl has 1, 2"),
        (lambda: suite.task("nope"), "unknown task 'nope' of benchmark suite v1; tasks: paper, "
         "n16, n32, noise1"),
        (lambda: spikectl.register_env_variant("spikectl/Bad", {}),
         "an environment variant's id reads 'namespace/Name-vN'"),
        (lambda: spikectl.register_env_variant("spikectl/Bad-v0", {"n_trian": 3}),
         "variant 'spikectl/Bad-v0': n_trian not an argument of NeuronControlEnv"),
        (lambda: spikectl.register_env_variant("spikectl/NeuronControlNoisy-v0", {}),
         "a variant named 'spikectl/NeuronControlNoisy-v0' is already registered"),
        (lambda: spikectl.register_controller("oracle", lambda played, seed: DoNothing(), ""),
         "a controller named 'oracle' is already registered"),
    ],
)  # fmt: skip
def test_unknown_or_taken_names_are_refused_in_one_line(call, message):
    with pytest.raises((RegistryError, FileNotFoundError)) as caught:
        call()
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_benchmark_refuses_an_unknown_suite_version_in_one_line(capsys):
    code, _, stderr = run_main(["benchmark", "do-nothing", "--suite", "7"], capsys)
    assert code == 2
    assert stderr.count("\n") == 1
    assert "unknown benchmark suite version '7'; this spikectl has 1" in stderr
