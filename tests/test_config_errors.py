"""Config errors are data (issue 22): every config refuses a bad value with a ConfigError
whose path names the field in the tree, and the command line names the flag from that
path (a lookup in tyro's naming), never from the message."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

from spikectl.agents import AgentSizes
from spikectl.cli import DemoConfig, TrainCommand, flag_for, main
from spikectl.config_errors import ConfigError
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.training.config import AgentConfig, EnvConfig, Experiment, TrainConfig
from spikectl.training.learners import DQNConfig
from spikectl.training.presets import SMOKE

NOISY = "spikectl/NeuronControlNoisy-v0"


def refusal(build) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        build()
    return info.value


# --- The path of each section's fields ------------------------------------------------


@pytest.mark.parametrize(
    ("changes", "path", "message"),
    [({"env.n_train": 0}, ("env", "n_train"), "n_train must be a positive integer, got 0"),
     ({"env.params.dt_ms": 0.0}, ("env", "params", "dt_ms"),
      "NeuronParams.dt_ms must be > 0, got 0.0"),
     ({"env.params.release_scale": 2.0}, ("env", "params", "release_scale"),
      "release_scale must lie in [0, 1], got 2.0"),
     ({"env.extensions.threshold_spread": 1.0}, ("env", "extensions", "threshold_spread"),
      "Extensions.threshold_spread must lie in [0, 1), got 1.0"),
     ({"env.extensions.hidden_neurons": 7}, ("env", "extensions", "hidden_neurons"),
      "extensions.hidden_neurons: 7 hidden neurons of 5 leave fewer than 2 observable ones "
      "(the target and one neuron to stimulate)"),
     ({"agent.arch": "nope"}, ("agent", "arch"),
      "arch must be one of ('drqn', 'ddrqn', 'dmdrqn', 'tdrqn'), got 'nope'"),
     ({"agent.sizes.lstm_hidden": 0}, ("agent", "sizes", "lstm_hidden"),
      "AgentSizes.lstm_hidden must be an int >= 1, got 0"),
     ({"agent.sizes.attn_heads": 3}, ("agent", "sizes", "attn_heads"),
      "AgentSizes.attn_heads (3) must divide AgentSizes.attn_width (16)"),
     ({"train.num_envs": 0}, ("train", "num_envs"), "num_envs must be a positive integer, got 0"),
     ({"train.total_env_steps": 10}, ("train", "total_env_steps"),
      "total_env_steps (10) is less than one round of num_envs x episode_length (160)"),
     ({"learner.gamma": 2.0}, ("learner", "gamma"), "gamma must lie in [0, 1], got 2.0")],
)  # fmt: skip
def test_a_config_error_carries_the_fields_path_in_the_tree(changes, path, message):
    error = refusal(lambda: SMOKE.with_changes(changes))
    assert error.path == path
    assert str(error) == message  # the message as it always read
    assert isinstance(error, ValueError)


@pytest.mark.parametrize(
    ("build", "path", "message"),
    [(lambda: EnvConfig(n_val=-1), ("n_val",), "n_val must be a non-negative integer, got -1"),
     (lambda: EnvConfig(id=3), ("id",), "env must be a registered environment id, got 3"),
     (lambda: EnvConfig(params={}), ("params",), "params must be a NeuronParams, got {}"),
     (lambda: AgentConfig(sizes=None), ("sizes",), "sizes must be an AgentSizes, got None"),
     (lambda: AgentSizes(inputs="target"), ("inputs",),
      "AgentSizes.inputs must be a sequence of feature names, got 'target'"),
     (lambda: AgentSizes(inputs=("target", "proximity", "target")), ("inputs",),
      "AgentSizes.inputs names target more than once"),
     (lambda: AgentSizes(head_hidden=(0,)), ("head_hidden",),
      "AgentSizes.head_hidden must be a sequence of ints >= 1, got (0,)"),
     (lambda: AgentSizes(do_nothing_head="x"), ("do_nothing_head",),
      "AgentSizes.do_nothing_head must be one of ('dueling', 'pooled'), got 'x'"),
     (lambda: NeuronParams(v_threshold_mV=-80.0), ("v_threshold_mV",),
      "v_threshold_mV (-80.0) must be above v_rest_mV (-70.0)"),
     (lambda: NeuronParams(capacitance_pF=float("nan")), ("capacitance_pF",),
      "NeuronParams.capacitance_pF must be finite, got nan"),
     (lambda: NeuronParams(refractory_steps=-1), ("refractory_steps",),
      "refractory_steps must be an integer in 0..1073741824, got -1"),
     (lambda: NeuronParams(dt_ms=30.0), ("dt_ms",),
      "dt_ms exceeds the membrane time constant R*C: the Euler step would overshoot rest"),
     (lambda: Extensions(hidden_neurons=-1), ("hidden_neurons",),
      "Extensions.hidden_neurons must be >= 0, got -1"),
     (lambda: Extensions(hidden_neurons=1, hidden_fraction=0.5), ("hidden_fraction",),
      "give hidden_neurons or hidden_fraction, not both"),
     (lambda: Extensions(background_rate=-1.0), ("background_rate",),
      "Extensions.background_rate must be >= 0, got -1.0"),
     (lambda: Extensions(bleaching_time_constant_steps=0.0), ("bleaching_time_constant_steps",),
      "Extensions.bleaching_time_constant_steps must be > 0 or None, got 0.0"),
     (lambda: TrainConfig(device=""), ("device",),
      "device must be a string such as cpu or cuda, got ''"),
     (lambda: DQNConfig(tau=0.0), ("tau",), "tau must lie in (0, 1], got 0.0")],
)  # fmt: skip
def test_each_config_names_its_own_field(build, path, message):
    """A config alone names the field within itself; the enclosing config lengthens it."""
    error = refusal(build)
    assert (error.path, str(error)) == (path, message)


def test_a_variant_with_the_base_settings_is_refused_on_env_id():
    error = refusal(lambda: EnvConfig(id=NOISY))
    assert error.path == ("id",) and str(error).startswith(f"env: {NOISY} sets ")
    assert error.within("env").naming("--env").startswith(f"--env: {NOISY} sets ")


def test_within_naming_and_pickling_keep_the_message():
    error = ConfigError("dt_ms", "must be > 0, got 0", label="NeuronParams.dt_ms")
    outer = error.within("env", "params")
    assert (outer.path, outer.dotted, str(outer)) == (
        ("env", "params", "dt_ms"), "env.params.dt_ms", "NeuronParams.dt_ms must be > 0, got 0"
    )  # fmt: skip
    assert outer.naming("--params.dt-ms") == "--params.dt-ms must be > 0, got 0"
    copy = pickle.loads(pickle.dumps(outer))
    assert (copy.path, str(copy)) == (outer.path, str(outer))
    assert copy.naming("-x") == "-x must be > 0, got 0"
    both = ConfigError("hidden_fraction", "give one, not both", label="")
    assert (str(both), both.naming("--f")) == ("give one, not both", "--f: give one, not both")


# --- The flag of a path ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("path", "flag"),
    [(("config", "env", "id"), "--env"),
     (("config", "env", "n_train"), "--n-train"),
     (("config", "env", "params", "dt_ms"), "--params.dt-ms"),
     (("config", "env", "params", "v_threshold_mV"), "--params.v-threshold-mV"),
     (("config", "env", "extensions", "hidden_neurons"), "--extensions.hidden-neurons"),
     (("config", "agent", "arch"), "--arch"),
     (("config", "agent", "sizes", "lstm_hidden"), "--sizes.lstm-hidden"),
     (("config", "train", "seed"), "--seed"),
     (("config", "learner", "gamma"), "--gamma"),
     (("run_dir",), "--run-dir"),
     (("preset",), None),  # suppressed: the preset is the subcommand
     (("config", "env"), None),  # a section is no flag
     (("learner", "gamma"), None)],  # not a path of TrainCommand
)  # fmt: skip
def test_flag_for_follows_tyros_naming(path, flag):
    assert flag_for(path, TrainCommand) == flag
    assert flag_for(("n_test",), DemoConfig) == "--n-test"


def test_every_flag_of_the_table_is_a_flag_of_spikectl_train(capsys):
    from spikectl.cli.errors import field_flags

    shown = ""
    for preset in ("smoke", "guided", "pqn"):  # each learner's flags show under its preset
        with pytest.raises(SystemExit):
            main(["train", preset, "--help"])
        shown += capsys.readouterr().out
    flags = set(field_flags(TrainCommand).values())
    assert len(flags) > 60 and {flag for flag in flags if flag not in shown} == set()


# --- The command line names the flag --------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "line"),
    [(["--gamma", "2"], "--gamma must lie in [0, 1], got 2.0"),
     (["--learning-rate", "inf"], "--learning-rate must be finite, got inf"),
     (["--n-train", "0"], "--n-train must be a positive integer, got 0"),
     (["--num-envs", "0"], "--num-envs must be a positive integer, got 0"),
     (["--total-env-steps", "10"],
      "--total-env-steps (10) is less than one round of num_envs x episode_length (160)"),
     (["--sizes.lstm-hidden", "0"], "--sizes.lstm-hidden must be an int >= 1, got 0"),
     (["--sizes.attn-heads", "3"],
      "--sizes.attn-heads (3) must divide AgentSizes.attn_width (16)"),
     (["--params.dt-ms", "0"], "--params.dt-ms must be > 0, got 0.0"),
     (["--params.release-scale", "2"], "--params.release-scale must lie in [0, 1], got 2.0"),
     (["--params.v-threshold-mV", "-80"],
      "--params.v-threshold-mV (-80.0) must be above v_rest_mV (-70.0)"),
     (["--extensions.threshold-spread", "1"],
      "--extensions.threshold-spread must lie in [0, 1), got 1.0"),
     (["--extensions.hidden-neurons", "7"],
      "--extensions.hidden-neurons: 7 hidden neurons of 5 leave fewer than 2 observable "
      "ones (the target and one neuron to stimulate)"),
     (["--extensions.hidden-neurons", "2", "--extensions.hidden-fraction", "0.2"],
      "--extensions.hidden-fraction: give hidden_neurons or hidden_fraction, not both")],
)  # fmt: skip
def test_the_cli_names_the_flag_of_a_config_error(argv, line, tmp_path, capsys):
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "smoke", *argv, "--run-dir", str(tmp_path / "run")])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.splitlines() == [f"spikectl: error: {line}"]
    assert not (tmp_path / "run").exists()


def test_another_command_names_its_own_flag(capsys):
    """baselines --hidden-fraction reaches Extensions; its flag is the command's own."""
    with pytest.raises(SystemExit):
        main(["baselines", "--hidden-fraction", "2"])
    assert capsys.readouterr().err.splitlines() == [
        "spikectl: error: --hidden-fraction must lie in [0, 1), got 2.0"
    ]


@pytest.mark.parametrize(
    ("changes", "path", "message"),
    [({"explore_do_nothing": "0.5"}, ("learner", "explore_do_nothing"),
      "explore_do_nothing must be a number or None, got '0.5'"),
     ({"learner.learning_rate": "1e-3"}, ("learner", "learning_rate"),
      "learning_rate must be a number, got '1e-3'"),
     ({"learner.n_step": 1.5}, ("learner", "n_step"), "n_step must be an integer, got 1.5"),
     ({"learner.loss": "l1"}, ("learner", "loss"),
      "loss must be one of ('mse', 'huber'), got 'l1'"),
     ({"train.progress": "yes"}, ("train", "progress"),
      "progress must be true or false, got 'yes'"),
     ({"train.num_envs": 2.0}, ("train", "num_envs"), "num_envs must be an integer, got 2.0"),
     ({"env.train_contexts": 3}, ("env", "train_contexts"),
      "train_contexts must be a path or None, got 3")],
)  # fmt: skip
def test_a_wrong_type_is_refused_in_one_line_from_every_entry_point(changes, path, message):
    """Every part of the tree, the learner's included, checks its fields' types with the
    one checker (``check_field_types``): the same line from ``with_changes`` (and so a
    sweep file's overrides and grid), config.json (``from_dict``) and Python."""
    from spikectl.experiments.sweep import Sweep

    for build in (
        lambda: SMOKE.with_changes(changes),
        lambda: Sweep.from_dict({"base": "smoke", "overrides": changes, "grid": {}}),
    ):
        error = refusal(build)
        assert (error.path, str(error)) == (path, message)
    (value,) = changes.values()
    section, name = path
    values = SMOKE.to_dict()
    values[section][name] = value
    error = refusal(lambda: Experiment.from_dict(values))
    assert (error.path, str(error)) == (path, message)
    part = getattr(SMOKE, section)
    error = refusal(lambda: dataclasses.replace(part, **{name: value}))
    assert (error.path, str(error)) == ((name,), message)
