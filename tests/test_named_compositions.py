"""The named controller as data (spikectl/planning/named.py): which composition each
environment gets, and that the named compositions replay the committed suite results
exactly (docs/results/suite: identify-and-plan's return on every test network, the
oracle's mean per task)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from spikectl.neuron.extensions import Extensions
from spikectl.planning import Composition, IdentifyAndPlan, composition_name, named_composition
from spikectl.planning.named import (
    COMPOSITIONS,
    FAST_AS_EXACT_SPIKES,
    FAST_AS_PAPER,
    GAMBLE,
    KNOWN_SD_BACKGROUND,
    KNOWN_SD_FAST_LARGE,
    KNOWN_SD_LARGE,
    KNOWN_SD_STOCHASTIC_RELEASE,
    RIG_HYPOTHESES,
    composition,
)

SUITE = Path(__file__).resolve().parents[1] / "docs" / "results" / "suite"
NOISY = Extensions(observation_noise_mV=2.0)
STOCHASTIC = Extensions(stochastic_release=True)
HIDDEN = Extensions(hidden_fraction=0.25)
HETEROGENEOUS = Extensions(threshold_spread=0.1, time_constant_spread=0.2)
CHR2 = Extensions(actuator="chr2")


@pytest.mark.parametrize(
    ("extensions", "n", "fast", "name"),
    [
        (None, None, False, "paper"),
        (Extensions(), 8, False, "paper"),
        (None, 15, False, "paper"),
        (None, 16, False, "paper-16"),
        (None, 32, False, "paper-32"),
        (Extensions(), 32, False, "paper-32"),
        (None, 32, True, "paper-16-fast"),
        (None, 8, True, "paper"),
        (NOISY, 8, False, "noise"),
        (Extensions(observation_noise_mV=1.0, hidden_fraction=0.25), 8, False, "noise"),
        (NOISY, 32, False, "noise-16"),
        (NOISY, 16, True, "noise-16-fast"),
        (STOCHASTIC, 8, False, "stochastic"),
        (STOCHASTIC, 32, False, "stochastic-16"),
        (Extensions(background_rate=0.005), 8, False, "background"),
        (HETEROGENEOUS, 8, False, "heterogeneous"),
        (Extensions(synaptic_spread=0.2), 8, True, "heterogeneous"),
        (HIDDEN, 8, False, "hidden"),
        (Extensions(hidden_neurons=1), 8, False, "hidden"),
        (HIDDEN, 32, False, "hidden-16"),
        (Extensions(sensing="spikes"), 8, False, "spikes"),
        (Extensions(sensing="spikes", latency_steps=1), 8, True, "spikes-fast"),  # no QMDP
        (Extensions(sensing="spikes", stochastic_release=True), 8, False, "spikes"),
        (Extensions(sensing="spikes"), 16, False, "spikes-16"),
        (CHR2, 8, False, "chr2"),
        (Extensions(actuator="chr2", latency_steps=2), 8, False, "chr2"),
        (CHR2, 16, False, "chr2-16"),
        (CHR2, 8, True, "paper"),  # the teacher keeps the paper's composition
        (CHR2, 16, True, "paper-16-fast"),
        # The light is read by the paper's tracker alone: it comes before noise and the rest.
        (Extensions(actuator="chr2", observation_noise_mV=1.0), 8, False, "chr2"),
        (Extensions(actuator="chr2", threshold_spread=0.1), 8, False, "chr2"),
        (Extensions(actuator="chr2", observation_noise_mV=1.0), 8, True, "paper"),
        (Extensions(actuator="chr2", sensing="spikes"), 8, False, "rig"),
        (Extensions(sensing="spikes", background_rate=0.005), 8, False, "rig"),
        (Extensions(actuator="chr2", sensing="spikes", latency_steps=2,
                    background_rate=0.005), 8, False, "rig"),
        (Extensions(actuator="chr2", sensing="spikes"), 8, True, "spikes-fast"),  # refuses: slow
        (Extensions(actuator="chr2", sensing="spikes"), 16, False, "rig-16"),
    ],
)
def test_each_environment_gets_its_situations_composition(extensions, n, fast, name):
    assert composition_name(extensions, n, fast) == name
    assert named_composition(extensions, n, fast).name == name


@pytest.mark.parametrize("extensions", [
    {"observation_noise_mV": 1.0}, {"latency_steps": 2, "observation_noise_mV": 1.0},
    {"stochastic_release": True}, {"background_rate": 0.005}, {"threshold_spread": 0.1},
    {"time_constant_spread": 0.1}, {"synaptic_spread": 0.1}, {"hidden_neurons": 2},
])  # fmt: skip
@pytest.mark.parametrize("fast", [False, True])
def test_the_named_controller_plays_the_light_with_any_other_extension(extensions, fast):
    """Under the ChR2 light with another extension the named controller and its fast
    form (the guided teacher) play whole episodes legally: none picks a composition whose
    tracker cannot take the light (noise and heterogeneity once did, refused at the first
    step)."""
    from conftest import play_legally

    from spikectl import NeuronControlEnv
    from spikectl.planning import IdentifyAndPlan

    env = NeuronControlEnv(contexts={"n_train": 2, "n_test": 2},
                           extensions={"actuator": "chr2", **extensions})  # fmt: skip
    controller = IdentifyAndPlan(env.params, named_composition(env.extensions, 8, fast),
                                 extensions=env.extensions)  # fmt: skip
    play_legally(env, controller, [0])


def test_the_declared_compositions_hold_what_was_chosen():
    paper = composition("paper")
    assert paper == Composition()  # the constructor's default is the paper's
    noise = composition("noise")
    assert noise.estimator.kind == "bayes" and noise.observation.filter_voltage
    assert noise.observation.task_model
    stochastic = composition("stochastic")
    assert stochastic.estimator.known_sd == KNOWN_SD_STOCHASTIC_RELEASE
    assert stochastic.observation.task_model
    assert composition("background").estimator.known_sd == KNOWN_SD_BACKGROUND
    assert not composition("background").observation.task_model
    assert composition("heterogeneous").observation.task_model
    assert composition("hidden").estimator.kind == "relays"
    large = composition("stochastic-16")
    assert large.estimator.known_sd == KNOWN_SD_LARGE and large.decision.gamble.networks == 16
    assert large.observation == stochastic.observation
    assert composition("paper-32").estimator.kind == "particles"
    fast = composition("noise-16-fast")
    assert fast.estimator == noise.estimator.__class__("bayes", KNOWN_SD_FAST_LARGE)
    assert fast.decision.gamble is None
    assert set(COMPOSITIONS) == {"paper", "noise", "stochastic", "background",
                                 "heterogeneous", "hidden", "spikes", "chr2", "rig"}  # fmt: skip
    spikes = composition("spikes")
    assert spikes == Composition("spikes", spikes.estimator.__class__("spikes"),
                                 decision=spikes.decision.__class__(gamble=GAMBLE))  # fmt: skip
    assert GAMBLE.networks == 16
    # Its fast and real-time forms (the teacher's, identify-and-plan-realtime's) drop QMDP.
    assert composition("spikes-fast") == spikes.but("spikes-fast", decision=Composition().decision)
    assert composition("spikes-realtime").decision.gamble is None
    # The paper's situation has no QMDP below 16 neurons: its fast form is itself.
    assert composition("paper-fast") == composition("paper").but("paper-fast")
    chr2 = composition("chr2")
    assert chr2 == Composition("chr2", chr2.estimator.__class__("bayes"))  # the rest: paper's
    assert FAST_AS_PAPER == ("chr2",)
    rig = composition("rig")
    assert rig == Composition("rig", rig.estimator.__class__("spike-likelihood"),
                              rig.observation.__class__(task_model=True),
                              rig.decision.__class__(hypotheses=RIG_HYPOTHESES))  # fmt: skip
    assert RIG_HYPOTHESES == 8 and rig.decision.draws == 8
    assert FAST_AS_EXACT_SPIKES == ("rig",)


@pytest.mark.parametrize(
    "extensions",
    [None, Extensions(), NOISY, STOCHASTIC, HIDDEN, HETEROGENEOUS,
     Extensions(background_rate=0.005)],
)  # fmt: skip
def test_below_16_neurons_the_fast_form_is_the_named_composition(extensions):
    assert named_composition(extensions, 8, fast=True) == named_composition(extensions, 8)
    assert named_composition(extensions, 15, fast=True) == named_composition(extensions, 15)
    fast = named_composition(extensions, 16, fast=True)
    assert fast.decision.gamble is None and fast.estimator.known_sd == KNOWN_SD_FAST_LARGE
    assert fast.observation == named_composition(extensions, 8).observation


@pytest.mark.parametrize("name", ["nothing", "noise-32", "paper-8", "paper-16-slow"])
def test_an_unknown_composition_is_refused_in_one_line(name):
    with pytest.raises(ValueError, match=f"unknown composition '{name}'") as caught:
        composition(name)
    assert "\n" not in str(caught.value)


def test_the_controller_names_what_it_plays_and_its_copies_play_the_same():
    policy = IdentifyAndPlan(composition=named_composition(NOISY, 8), extensions=NOISY, seed=3)
    assert policy.composition.name == "noise" and policy.noise_mV == 2.0
    copy = policy.spawn(2)
    assert copy.composition == policy.composition and copy.seed == 5
    assert copy.extensions is NOISY


def _committed(file: str, task: str) -> list[dict[str, str]]:
    with open(SUITE / file, newline="") as handle:
        return [row for row in csv.DictReader(handle) if row["task"] == task]


# Tasks whose environment draws nothing are replayed on their first networks; the others
# whole (a network's draws depend on the batch it is played in), which is cheap at n = 8.
REPLAYED = {
    "paper": 100, "n16": 3, "n32": 2, "noise1": 100, "noise2": 100, "noise4": 100,
    "hidden25": 100, "stochastic": 100, "heterogeneous": 100, "background": 100,
}  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize(("task", "count"), list(REPLAYED.items()))
def test_the_named_controller_replays_the_committed_per_network_returns(task, count):
    """Every return identical to the committed one, network by network (the benchmark's
    protocol: the task's split, extensions and environment seed)."""
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments import suite
    from spikectl.training.loaders import load_controller

    contexts = suite.load_split(task, "test")[:count]
    extensions = suite.task(task).extensions
    controller = load_controller(
        "identify-and-plan", env=NeuronControlEnv(contexts=contexts, extensions=extensions)
    )
    returns = evaluate_policy(contexts, controller, extensions=extensions,
                              seed=suite.suite_version(1).env_seed).returns  # fmt: skip
    rows = sorted(_committed("identify-and-plan-per-network.csv", task),
                  key=lambda row: int(row["context"]))[:count]  # fmt: skip
    assert [repr(float(value)) for value in returns] == [row["return"] for row in rows]


@pytest.mark.slow
@pytest.mark.parametrize("task", list(REPLAYED))
def test_the_oracle_replays_its_committed_mean_return(task):
    from spikectl.experiments import suite
    from spikectl.training.loaders import load_controller

    contexts = suite.load_split(task, "test")
    returns, _ = suite.play(task, "test", load_controller("oracle", contexts=contexts))
    (row,) = _committed("oracle.csv", task)
    assert f"{np.mean(returns):.6f}" == row["mean_return"]


SUITE_V2 = SUITE.parent / "suite-v2"
REPLAYED_V2 = {"paper": 50, "latency2": 50, "spikes-only": 10, "chr2": 20, "rig": 4}


@pytest.mark.slow
@pytest.mark.parametrize(("task", "count"), list(REPLAYED_V2.items()))
def test_the_named_controller_replays_suite_v2s_committed_returns(task, count):
    """Suite v2's committed identify-and-plan returns, network by network, on the first
    test networks (network i is sub-environment i, seeded ``env_seed + i`` as in the
    whole set's batch, so ``rig``'s background input draws the same), each row its
    composition's."""
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments import suite
    from spikectl.training.loaders import load_controller

    contexts = suite.load_split(task, "test", 2)[:count]
    extensions = suite.task(task, 2).extensions
    controller = load_controller(
        "identify-and-plan", env=NeuronControlEnv(contexts=contexts, extensions=extensions)
    )
    returns = evaluate_policy(contexts, controller, extensions=extensions,
                              seed=suite.suite_version(2).env_seed).returns  # fmt: skip
    with open(SUITE_V2 / "identify-and-plan-per-network.csv", newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if row["task"] == task]
    rows = sorted(rows, key=lambda row: int(row["context"]))[:count]
    assert [repr(float(value)) for value in returns] == [row["return"] for row in rows]
    assert {row["composition"] for row in rows} == {controller.composition.name}
