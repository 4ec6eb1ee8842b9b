"""The frozen benchmark suite (spikectl.experiments.suite) and ``spikectl benchmark``."""

from __future__ import annotations

import csv
import importlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import run_main

from spikectl.contexts import ContextSet
from spikectl.experiments import suite
from spikectl.experiments.suite import protocol

V1 = suite.suite_version(1)

SMOKE_RUN = Path(__file__).parent / "data" / "format2-smoke-run"


@pytest.fixture
def fresh_cache():
    """load_splits caches what it checked: start and end each test without that cache."""
    suite.load_splits.cache_clear()
    yield
    suite.load_splits.cache_clear()


@pytest.mark.parametrize("name", V1.names())
def test_every_task_builds_the_pinned_sets(name, fresh_cache):
    # All 10 tasks x 3 sets take about 4 s: checked in the default run.
    sets = suite.load_splits(name)
    spec = V1.task(name)
    assert set(sets) == set(suite.SPLITS) == set(spec.checksums)
    for split, contexts in sets.items():
        assert len(contexts) == V1.set_size == 100
        assert contexts.n_neurons == spec.n_neurons
        assert contexts.n_observed == spec.n_observed
        assert contexts.episode_length == V1.episode_length == 60
        assert contexts.extensions == spec.extensions.context_part()
        assert suite.suite_checksum(contexts) == spec.checksums[split]
    # No topology shared between the splits.
    assert not sets["test"].duplicate_topologies(sets["train"])
    assert not sets["validation"].duplicate_topologies(sets["test"])


def test_tasks_are_the_registered_variants():
    assert (V1.number, V1.frozen, V1.env_seed) == (1, True, 0)
    assert V1.names() == (
        "paper", "n16", "n32", "noise1", "noise2", "noise4", "hidden25", "stochastic",
        "heterogeneous", "background",
    )  # fmt: skip
    assert [V1.task(f"noise{s}").extensions.observation_noise_mV for s in (1, 2, 4)] == [
        1.0, 2.0, 4.0,
    ]  # fmt: skip
    assert V1.task("hidden25").n_observed == 6
    assert V1.task("stochastic").extensions.stochastic_release
    assert V1.task("background").extensions.background_rate == 0.005
    assert V1.task("heterogeneous").extensions.heterogeneous
    assert V1.task("paper").extensions == V1.task("n32").extensions.__class__()


def test_a_changed_generator_is_refused(monkeypatch, fresh_cache):
    real = protocol.make_splits

    def drifted(*args, **kwargs):  # a generator that now draws other networks
        return real(*args, **{**kwargs, "seed": kwargs["seed"] + 1})

    monkeypatch.setattr(protocol, "make_splits", drifted)
    with pytest.raises(suite.SuiteChecksumError, match=r"suite v1, task 'n16', train set"):
        suite.load_split("n16", "test")


def test_a_tampered_set_is_refused(monkeypatch, fresh_cache):
    sets = suite.generate_splits("paper")
    contexts = list(sets["validation"])
    contexts[0], contexts[1] = contexts[1], contexts[0]  # the same networks, another order
    tampered = {**sets, "validation": ContextSet(contexts, sets["validation"].params)}
    monkeypatch.setattr(protocol, "generate_splits", lambda name, version: tampered)
    expected = "suite v1, task 'paper', validation set.*a new suite version"
    with pytest.raises(suite.SuiteChecksumError, match=expected):
        suite.load_split("paper", "test")


def test_the_checksum_sees_every_defining_array():
    contexts = suite.generate_splits("hidden25")["test"][:3]
    base = suite.suite_checksum(contexts)
    first = contexts[0]
    other_pattern = first.pattern.copy()
    other_pattern[0] = not other_pattern[0]
    changed = type(first)(first.weights, first.target, other_pattern, None, first.hidden)
    assert suite.suite_checksum(ContextSet([changed, *contexts[1:]], contexts.params)) != base


def test_normalisation_on_hand_values():
    assert suite.normalise(0.5, 0.5, 0.9) == 0.0
    assert suite.normalise(0.9, 0.5, 0.9) == pytest.approx(1.0)
    assert suite.normalise(0.75, 0.5, 1.0) == pytest.approx(0.5)
    assert suite.normalise(0.4, 0.5, 1.0) == pytest.approx(-0.2)  # worse than nothing
    assert suite.mean_normalised({"paper": 0.2, "n32": 0.6}) == pytest.approx(0.4)
    with pytest.raises(ValueError, match="does not beat doing nothing"):
        suite.normalise(0.5, 0.5, 0.5)


def test_standard_error_on_hand_values():
    # sd of (0, 1, 2, 3) with ddof 1 is sqrt(5/3); over sqrt(4).
    assert suite.standard_error([0.0, 1.0, 2.0, 3.0]) == pytest.approx(np.sqrt(5 / 3) / 2)
    assert suite.standard_error(np.full(100, 0.5)) == 0.0
    assert np.isnan(suite.standard_error([0.7]))
    score = suite.Score("paper", "test", np.array([0.5, 1.0]), np.array([0.75]), 0.0)
    assert score.standard_error == pytest.approx(0.25)


def test_benchmark_do_nothing_on_paper(capsys, tmp_path):
    out = tmp_path / "scores.csv"
    code, stdout, _ = run_main(["benchmark", "do-nothing", "--task", "paper", "--out",
                                str(out)], capsys)  # fmt: skip
    assert code == 0
    row = next(line for line in stdout.splitlines() if line.startswith("paper"))
    assert row.split()[1:3] == ["0.500", "0.000"]
    assert "suite v1" in stdout
    lines = out.read_text().splitlines()
    assert lines[0].startswith("suite_version,task,split,controller")
    assert lines[1].startswith("1,paper,test,do-nothing,")


def test_benchmark_writes_each_networks_return(capsys, tmp_path):
    """--per-network: one row per test network whose mean is the task's mean return
    (for the random controller, each network's mean over its seeds)."""
    out, per_network = tmp_path / "scores.csv", tmp_path / "networks.csv"
    argv = ["benchmark", "random", "--task", "paper", "--random-seeds", "2", "--out", str(out),
            "--per-network", str(per_network)]  # fmt: skip
    code, _, _ = run_main(argv, capsys)
    assert code == 0
    with open(per_network, newline="") as file:
        rows = list(csv.DictReader(file))
    assert [int(row["context"]) for row in rows] == list(range(V1.set_size))
    assert {(row["task"], row["split"], row["controller"]) for row in rows} == {
        ("paper", "test", "random")
    }
    returns = np.array([float(row["return"]) for row in rows])
    with open(out, newline="") as file:
        (summary,) = csv.DictReader(file)
    assert float(summary["mean_return"]) == pytest.approx(returns.mean(), abs=1e-6)
    # The row carries the standard error over the networks, from the per-network returns.
    expected_error = returns.std(ddof=1) / np.sqrt(V1.set_size)
    assert float(summary["standard_error"]) == pytest.approx(expected_error, abs=1e-6)
    assert 0.0 <= returns.min() < returns.max() <= 1.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["do-nothing", "--task", "n64"], "unknown task 'n64' of benchmark suite v1"),
        (["no-such-controller", "--task", "paper"], "no controller 'no-such-controller'"),
        (["random", "--task", "paper", "--random-seeds", "0"], "--random-seeds must be"),
        (["do-nothing", "--task", "paper", "--out", "tests"], "--out tests: it is a folder"),
        (["do-nothing", "--per-network", "tests"], "--per-network tests: it is a folder"),
    ],
)
def test_benchmark_refuses_bad_input_in_one_line(argv, message, capsys):
    code, _, stderr = run_main(["benchmark", *argv], capsys)
    assert code == 2
    assert stderr.count("\n") == 1 and message in stderr


def copied_run(tmp_path, **env_changes) -> tuple[Path, dict]:
    run = tmp_path / "run"
    shutil.copytree(SMOKE_RUN, run)
    config = json.loads((run / "config.json").read_text())
    config["env"].update(env_changes)
    return run, config


def test_benchmark_refuses_a_fixed_size_network_on_another_n(tmp_path, capsys):
    run, config = copied_run(tmp_path, n_neurons=8, episode_length=60)
    config["agent"]["arch"] = "drqn"
    (run / "config.json").write_text(json.dumps(config))
    code, _, stderr = run_main(["benchmark", str(run), "--task", "n32"], capsys)
    assert code == 2 and stderr.count("\n") == 1
    assert "cannot play task 'n32'" in stderr and "DRQN has a fixed input of 8" in stderr
    # Another neuron model, or another episode length, is refused whatever the network.
    config["agent"]["arch"] = "tdrqn"
    config["env"]["params"]["stimulus_current_pA"] = 900.0
    (run / "config.json").write_text(json.dumps(config))
    code, _, stderr = run_main(["benchmark", str(run), "--task", "paper"], capsys)
    assert code == 2 and "other neuron parameters" in stderr
    code, _, stderr = run_main(["benchmark", str(SMOKE_RUN), "--task", "n32"], capsys)
    assert code == 2 and "episodes of 20 steps" in stderr


def test_a_per_neuron_network_may_play_any_n(tmp_path):
    from spikectl.training.run_files import read_config

    run, config = copied_run(tmp_path, n_neurons=8, episode_length=60)
    (run / "config.json").write_text(json.dumps(config))
    assert config["agent"]["arch"] == "tdrqn"
    for name in ("paper", "n16", "n32", "hidden25"):
        suite.check_run_fits(read_config(run), name)  # no refusal


@pytest.mark.parametrize("name", V1.names())
def test_train_task_flag_trains_on_the_tasks_pinned_sets(name):
    """``spikectl train --task T`` generates exactly the suite's training, test and
    validation sets of T (their pinned checksums), with T's environment and extensions,
    and trained_on recognises the run as T's (and no other task's)."""
    from spikectl.cli.training import parse_train
    from spikectl.training.run_sets import generated_contexts, make_validation_set

    config = parse_train(["quick", "--task", name, "--seed", "3"]).config
    env, spec = config.env, suite.task(name)
    assert (env.id, env.n_neurons, env.extensions) == (spec.env_id, spec.n_neurons,
                                                       spec.extensions)  # fmt: skip
    train, test = generated_contexts(config)
    validation = make_validation_set(
        env.n_val, (train, test), env.n_neurons, env.episode_length, env.context_seed,
        params=env.params, extensions=env.extensions,
    )  # fmt: skip
    for split, contexts in (("train", train), ("test", test), ("validation", validation)):
        assert suite.suite_checksum(contexts) == spec.checksums[split], split
    assert suite.trained_on(config, train) == name


def test_train_task_flag_pins_the_task_sets_over_the_presets_sizes():
    """The guided preset trains on 1 000 networks; --task still gives the task's 100
    (its pinned training set), and a later --n-train still overrides the task."""
    from spikectl.cli.training import parse_train
    from spikectl.training.presets import PRESETS
    from spikectl.training.run_sets import generated_contexts

    assert PRESETS["guided"].env.n_train == 1000
    config = parse_train(["guided", "--task", "paper"]).config
    assert (config.env.n_train, config.env.n_test, config.env.n_val) == (100, 100, 100)
    train, _ = generated_contexts(config)
    assert suite.suite_checksum(train) == V1.task("paper").checksums["train"]
    assert parse_train(["guided", "--task", "paper", "--n-train", "20"]).config.env.n_train == 20


def test_train_task_flag_is_overridden_by_later_flags_and_checked():
    from spikectl.cli.training import parse_train
    from spikectl.training.run_sets import generated_contexts

    config = parse_train(["guided", "--task=noise1", "--extensions.observation-noise-mV",
                          "3"]).config  # fmt: skip
    assert config.env.extensions.observation_noise_mV == 3.0
    assert config.learner.name == "guided"
    # Off the suite: no task recognises the run.
    train, _ = generated_contexts(config)
    assert suite.trained_on(config, train) is None
    for argv, message in (
        (["--task", "n64"], "unknown task 'n64' of benchmark suite v1"),
        (["--task", "paper", "--task", "n16"], "one task per run"),
        (["--task"], "give a task of the benchmark suite"),
        (
            ["--task", "paper", "--train-contexts", "c.npz"],
            "--task paper trains on the task's pinned sets, --train-contexts on a file",
        ),
        (["--task=n16", "--test-contexts=c.npz"], "--test-contexts on a file of its own"),
    ):
        with pytest.raises(ValueError, match=message):
            parse_train(argv)


V2 = suite.suite_version(2)


def test_v2_is_the_rigs_loop_on_1000_networks_beside_a_frozen_v1(fresh_cache):
    assert (V2.number, V2.frozen, V2.set_size, V2.env_seed) == (2, False, 1000, 0)
    assert V2.names() == ("paper", "latency1", "latency2", "spikes-only", "chr2", "rig")
    assert [V2.task(name).extensions.latency_steps for name in V2.names()] == [0, 1, 2, 0, 0, 2]
    assert [V2.task(name).extensions.sensing for name in V2.names()] == ["potentials"] * 3 + [
        "spikes", "potentials", "spikes"
    ]
    assert [V2.task(name).extensions.actuator for name in V2.names()] == ["pulse"] * 4 + [
        "chr2", "chr2"
    ]
    assert [V2.task(name).extensions.background_rate for name in V2.names()] == [0.0] * 5 + [
        0.005
    ]
    # The chr2 and rig tasks play the paper's networks (the same pinned checksums).
    assert suite.load_split("chr2", "test", 2) == suite.load_split("paper", "test", 2)
    assert suite.load_split("rig", "test", 2) == suite.load_split("paper", "test", 2)
    assert {V2.task(name).seed for name in V2.names()} == {2}
    sets = suite.load_splits("latency1", 2)  # checked against the pinned checksums
    assert [len(sets[split]) for split in suite.SPLITS] == [1000, 1000, 1000]
    assert sets["test"] == suite.load_split("paper", "test", 2)  # the paper's networks
    assert not sets["test"].duplicate_topologies(sets["train"])
    # No v2 network is one of v1's test networks: a seed of its own.
    assert not sets["test"].duplicate_topologies(suite.load_split("paper", "test", 1))
    assert suite.load_split("paper", "test", 1) != sets["test"]


def test_benchmark_plays_a_v2_task_under_its_latency(capsys, tmp_path):
    out = tmp_path / "v2.csv"
    code, stdout, _ = run_main(["benchmark", "do-nothing", "--suite", "2", "--task", "latency2",
                                "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, stdout
    assert "benchmark suite v2" in stdout and "1000 contexts" in stdout
    (row,) = list(csv.DictReader(out.open()))
    assert (row["suite_version"], row["task"], row["contexts"]) == ("2", "latency2", "1000")
    assert float(row["mean_return"]) == 0.5  # doing nothing: half the pattern's steps right


def test_a_benchmark_of_the_oracle_plays_it_once_and_reads_its_reference(
    capsys, tmp_path, monkeypatch
):
    """The oracle's row and the normalised score's 1 are the same episodes: the task is
    played once by each reference controller, never by the oracle a second time."""
    played = []
    real_play = protocol.play

    def counting_play(name, split, controller, version=1):
        played.append(type(controller).__name__)
        return real_play(name, split, controller, version)

    monkeypatch.setattr(protocol, "play", counting_play)
    protocol.reference_scores.cache_clear()
    out = tmp_path / "oracle.csv"
    code, stdout, _ = run_main(["benchmark", "oracle", "--task", "paper", "--out", str(out)],
                               capsys)  # fmt: skip
    protocol.reference_scores.cache_clear()
    assert code == 0, stdout
    assert sorted(played) == ["DoNothing", "OraclePlanner"]
    (row,) = list(csv.DictReader(out.open()))
    assert row["mean_return"] == row["oracle"] and float(row["normalised"]) == 1.0
    assert float(row["cpu_seconds"]) > 0


def test_a_task_the_controller_cannot_play_is_refused_before_any_episode(
    capsys, tmp_path, monkeypatch
):
    """Named, a task the controller refuses is one line, exit 2, before anything is played
    or written. (Identify-and-plan now plays every v2 task: the refusal is stood in.)"""
    benchmark = importlib.import_module("spikectl.cli.benchmark")

    def refuse_rig(make, name, split, version):
        return "it cannot read background_rate" if name == "rig" else None

    monkeypatch.setattr(benchmark, "task_refusal", refuse_rig)
    out = tmp_path / "rows.csv"
    code, stdout, stderr = run_main(["benchmark", "identify-and-plan", "--suite", "2", "--task",
                                     "paper", "rig", "--out", str(out)], capsys)  # fmt: skip
    assert code == 2 and not out.exists()
    (line,) = stderr.strip().splitlines()
    assert "cannot play task 'rig'" in line and "background_rate" in line


def test_identify_and_plan_plays_the_rig_task():
    """The named controller plays v2's ``rig`` (its ``rig`` composition): no refusal."""
    from spikectl.cli.benchmark import task_refusal
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.training.loaders import load_controller

    def make(name):
        env = NeuronControlEnv(contexts=suite.load_split(name, "validation", 2),
                               extensions=suite.task(name, 2).extensions)  # fmt: skip
        return lambda seed: load_controller("identify-and-plan", env=env, seed=seed)

    assert task_refusal(make, "rig", "validation", 2) is None


def test_all_tasks_skips_those_the_controller_cannot_play(capsys, tmp_path, monkeypatch):
    """Under --task all a task the controller cannot play is skipped with its reason, and
    the others are played and written."""
    benchmark = importlib.import_module("spikectl.cli.benchmark")

    def refuse_all_but_paper(make, name, split, version):
        return None if name == "paper" else f"cannot read {name}"

    monkeypatch.setattr(benchmark, "task_refusal", refuse_all_but_paper)
    out = tmp_path / "rows.csv"
    code, stdout, _ = run_main(["benchmark", "do-nothing", "--task", "all", "--out", str(out)],
                               capsys)  # fmt: skip
    assert code == 0, stdout
    assert [row["task"] for row in csv.DictReader(out.open())] == ["paper"]
    assert "n16            skipped: do-nothing cannot play it (cannot read n16)" in stdout


def test_the_first_decision_says_why_a_controller_cannot_play():
    from spikectl.envs.controller import DoNothing, first_decision_refusal
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.planning import IdentifyAndPlan

    env = NeuronControlEnv(contexts={"n_train": 2, "n_test": 2},
                           extensions={"sensing": "spikes"})  # fmt: skip
    assert first_decision_refusal(env, DoNothing) is None
    why = first_decision_refusal(env, lambda: IdentifyAndPlan(env.params))  # for potentials
    assert why is not None and "\n" not in why and "spikes" in why
    rig = suite.task("rig", 2).extensions
    why = first_decision_refusal(env, lambda: IdentifyAndPlan(env.params, extensions=rig))
    assert why is not None and "\n" not in why and "actuator='chr2'" in why


def test_a_benchmark_row_carries_its_decision_times(capsys, tmp_path):
    """decision_p50_ms / decision_p99_ms: each decision of --decision-episodes episodes
    timed alone (0 ≤ p50 ≤ p99); 0 episodes leaves the columns empty; more episodes than
    the set has networks is one line, exit 2, before anything is played."""
    timed, untimed = tmp_path / "timed.csv", tmp_path / "untimed.csv"
    for out, episodes in ((timed, "3"), (untimed, "0")):
        code, stdout, _ = run_main(["benchmark", "identify-and-plan", "--task", "paper",
                                    "--decision-episodes", episodes, "--out", str(out)],
                                   capsys)  # fmt: skip
        assert code == 0, stdout
    (row,) = list(csv.DictReader(timed.open()))
    assert 0 < float(row["decision_p50_ms"]) <= float(row["decision_p99_ms"])
    (bare,) = list(csv.DictReader(untimed.open()))
    assert bare["decision_p50_ms"] == bare["decision_p99_ms"] == ""
    assert bare["mean_return"] == row["mean_return"]  # timing plays apart from the score
    code, _, stderr = run_main(["benchmark", "do-nothing", "--task", "paper",
                                "--decision-episodes", "101"], capsys)  # fmt: skip
    assert code == 2
    (line,) = stderr.strip().splitlines()
    assert "--decision-episodes must be an integer in 0..100" in line and "101" in line
