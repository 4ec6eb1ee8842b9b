"""Identify-and-plan's real-time form (the ``-realtime`` compositions, the registered
``identify-and-plan-realtime``): what it plays, that it is the fast form at a narrower
beam, and that it replays its committed returns (docs/results/realtime-iap)."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import pytest

from spikectl.neuron.extensions import Extensions
from spikectl.planning import composition_name, named_composition
from spikectl.planning.named import KNOWN_SD_FAST_LARGE, REALTIME_WIDTH, composition

RECORD = Path(__file__).resolve().parents[1] / "docs" / "results" / "realtime-iap"


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
def test_the_realtime_form_is_the_fast_form_at_a_narrower_beam(extensions, n, name):
    assert composition_name(extensions, n, realtime=True) == name
    realtime = named_composition(extensions, n, realtime=True)
    fast = named_composition(extensions, n, fast=True)
    assert realtime.name == name
    assert realtime.decision == replace(fast.decision, width=REALTIME_WIDTH)
    assert (realtime.estimator, realtime.observation, realtime.prober) == (
        fast.estimator, fast.observation, fast.prober)  # fmt: skip
    assert named_composition(extensions, n, fast=True, realtime=True) == realtime


def test_the_declared_realtime_compositions():
    large = composition("paper-16-realtime")
    assert large.estimator.known_sd == KNOWN_SD_FAST_LARGE and large.decision.gamble is None
    assert large.decision.width == REALTIME_WIDTH < composition("paper-16-fast").decision.width
    assert composition("hidden-realtime").estimator.kind == "relays"
    with pytest.raises(ValueError, match="unknown composition 'paper-32-realtime'"):
        composition("paper-32-realtime")


def test_the_registered_controller_plays_the_realtime_form(run_cli):
    from spikectl import make_splits
    from spikectl.training.loaders import CONTROLLERS, load_controller

    assert "identify-and-plan-realtime" in CONTROLLERS
    contexts = make_splits(2, 1, 16, seed=3)[0]
    assert load_controller("identify-and-plan-realtime", contexts=contexts).composition.name \
        == "paper-16-realtime"  # fmt: skip
    result = run_cli("realtime", "identify-and-plan-realtime", "--episodes", "2")
    assert "IdentifyAndPlan paced at 1000 Hz" in result.stdout


def _committed(task: str) -> list[str]:
    with open(RECORD / "test-per-network.csv", newline="") as handle:
        rows = [row for row in csv.DictReader(handle)
                if row["task"] == task and row["form"] == "realtime"]  # fmt: skip
    return [row["return"] for row in sorted(rows, key=lambda row: int(row["context"]))]


@pytest.mark.parametrize(("task", "count"), [("paper", 20), ("n16", 4)])
def test_identify_and_plan_realtime_replays_its_committed_returns(task, count):
    """The registered controller, network by network, as the record played it (the
    suite's protocol; these environments draw nothing, so a prefix replays)."""
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.envs.rollout import evaluate_policy
    from spikectl.experiments import suite
    from spikectl.training.loaders import load_controller

    contexts = suite.load_split(task, "test")[:count]
    extensions = suite.task(task).extensions
    controller = load_controller("identify-and-plan-realtime",
                                 env=NeuronControlEnv(contexts=contexts, extensions=extensions))
    returns = evaluate_policy(contexts, controller, extensions=extensions,
                              seed=suite.suite_version(1).env_seed).returns  # fmt: skip
    assert [repr(float(value)) for value in returns] == _committed(task)[:count]
