"""The configuration tree end to end: variants, model parameters and extensions reach
the environment and the agent's input, and config.json rebuilds the same run."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from spikectl import ContextSet, NeuronParams
from spikectl.agents.inputs import per_neuron_inputs
from spikectl.cli import main
from spikectl.training.checkpoint import read_checkpoint
from spikectl.training.config import Experiment
from spikectl.training.evaluate import evaluate_run
from spikectl.training.learners.q_learning import build_networks
from spikectl.training.loaders import load_agent
from spikectl.training.presets import SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import read_config, read_metrics

NOISY = "spikectl/NeuronControlNoisy-v0"
SHORT = SMOKE.with_changes(total_env_steps=2 * 8 * 20, eval_every_episodes=8,
                           checkpoint_every_episodes=16)  # fmt: skip
OTHER_PARAMS = NeuronParams(v_rest_mV=-65.0, v_threshold_mV=-45.0, capacitance_pF=25.0)


def first_voltages(run_dir) -> np.ndarray:
    """The observed potentials at step 0 of every stored episode [E, n]."""
    (learner,) = read_checkpoint(run_dir / "checkpoint.pt")["learners"]["seeds"]
    return learner["replay"]["voltage"][:, 0].numpy()


def test_training_on_the_noisy_variant_applies_its_noise(tmp_path):
    plain = train(SHORT, tmp_path / "plain")
    noisy_config = SHORT.with_changes({"env.id": NOISY})
    noisy = train(noisy_config, tmp_path / "noisy")
    # Noise-free, every episode starts at rest; with 2 mV of noise, no reading is -70.
    assert np.all(first_voltages(tmp_path / "plain") == -70.0)
    start = first_voltages(tmp_path / "noisy")
    assert np.all(start != -70.0) and 1.5 < float(np.std(start + 70.0)) < 2.5
    assert [row["train_return"] for row in plain] != [row["train_return"] for row in noisy]
    # Deterministic all the same: the environment's draws come from the training seed.
    again = train(noisy_config, tmp_path / "again")
    assert [row["train_return"] for row in again] == [row["train_return"] for row in noisy]
    np.testing.assert_array_equal(first_voltages(tmp_path / "again"), start)
    # config.json records the variant and its settings; evaluate rebuilds that environment.
    saved = json.loads((tmp_path / "noisy" / "config.json").read_text())
    assert saved["env"]["id"] == NOISY and saved["env"]["extensions"]["observation_noise_mV"] == 2
    assert read_config(tmp_path / "noisy") == noisy_config
    results = {result.name: result.mean for result in evaluate_run(tmp_path / "noisy")}
    assert results["train"] == noisy[-1]["train_return"]
    assert results["test"] == noisy[-1]["test_return"]


def test_contexts_with_other_params_train_normalised_by_those_params(tmp_path, capsys):
    """A context set made with other NeuronParams: the run's environment simulates them
    and the agent's input is normalised by them (rest -> 0, threshold -> 1)."""
    train_set, test_set = (ContextSet.generate(6, n_neurons=5, episode_length=20, seed=s,
                                               params=OTHER_PARAMS) for s in (1, 2))  # fmt: skip
    train_set.save(tmp_path / "train.npz")
    test_set.save(tmp_path / "test.npz")
    files = {"train_contexts": tmp_path / "train.npz", "test_contexts": tmp_path / "test.npz",
             "n_val": 0}  # fmt: skip
    with pytest.raises(ValueError, match=r"params: the config's \(--params.\*\) differ from "
                       "those the training contexts were made with: v_rest_mV -70.0 "
                       r"\(theirs: -65.0\)"):  # fmt: skip
        train(SHORT.with_changes(files), tmp_path / "refused")
    config = SHORT.with_changes({**files, "env.params": OTHER_PARAMS})
    train(config, tmp_path / "run")
    # Its agent plays only contexts of those params (one check, the contexts' own).
    ContextSet.generate(2, n_neurons=5, episode_length=20, seed=3).save(tmp_path / "paper.npz")
    with pytest.raises(ValueError, match="was trained on .* differ from those .*paper.npz were"):
        evaluate_run(tmp_path / "run", contexts=tmp_path / "paper.npz")
    # The real-time rig generates its set with the run's params, and refuses others.
    main(["realtime", str(tmp_path / "run"), "--episodes", "1", "--rate-hz", "1e6"])
    with pytest.raises(SystemExit, match="2"):
        main(["realtime", str(tmp_path / "run"), "--contexts", str(tmp_path / "paper.npz")])
    assert "capacitance_pF 25.0 (theirs: 30.0)" in capsys.readouterr().err
    online, _ = build_networks(config)
    assert (online.v_rest_mV, online.v_threshold_mV) == (-65.0, -45.0)
    # Every stored episode starts at the other resting potential, which the agent sees as 0.
    voltage = torch.as_tensor(first_voltages(tmp_path / "run"))  # [E, n]
    assert torch.all(voltage == -65.0)
    obs = {"voltage": voltage, "last_action": torch.full((voltage.shape[0],), -1),
           "target": torch.zeros(voltage.shape[0], dtype=torch.long)}  # fmt: skip
    features = per_neuron_inputs(obs, (), v_rest_mV=online.v_rest_mV,
                                 v_threshold_mV=online.v_threshold_mV,
                                 dtype=torch.float32)  # fmt: skip
    assert torch.all(features[..., 0] == 0.0)
    agent = load_agent(tmp_path / "run")
    assert (agent.v_rest_mV, agent.v_threshold_mV) == (-65.0, -45.0)


def test_hidden_neurons_train_on_the_observed_ones(tmp_path):
    config = SHORT.with_changes({"env.id": "spikectl/NeuronControlPartial-v0", "n_neurons": 6})
    assert config.env.n_observed == 4  # round(0.25 * 6) = 2 hidden (halves up)
    metrics = train(config, tmp_path / "run")
    assert first_voltages(tmp_path / "run").shape[1] == 4
    assert read_metrics(tmp_path / "run")[-1]["train_return"] == metrics[-1]["train_return"]


def cli_error(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize(
    ("flags", "named"),
    [(["--env", "spikectl/Nope-v0"], "--env: unknown environment id 'spikectl/Nope-v0'"),
     (["--env", "CartPole-v1"], "--env: 'CartPole-v1' is not a spikectl environment"),
     (["--params.v-rest-mV", "-40"], "--params.v-threshold-mV (-50.0) must be above"),
     (["--params.capacitance-pF", "0"], "--params.capacitance-pF must be > 0"),
     (["--params.release-scale", "2"], "--params.release-scale must lie in [0, 1]"),
     (["--params.v-rest-mV", "abc"], "--params.v-rest-mV"),
     (["--extensions.observation-noise-mV", "-1"],
      "--extensions.observation-noise-mV must be >= 0"),
     (["--env", NOISY, "--extensions.observation-noise-mV", "-1"],
      "--extensions.observation-noise-mV must be >= 0"),
     (["--extensions.hidden-fraction", "0.9"], "--extensions.hidden-fraction: 5 hidden neurons"),
     (["--env", NOISY, "--extensions.observation-noise-mV", "0"],
      "--env: spikectl/NeuronControlNoisy-v0 sets extensions.observation_noise_mV = 2.0"),
     (["--preset", "smoke"], "--preset: the preset is a subcommand now")],
)  # fmt: skip
def test_bad_environment_flags_are_one_line_errors(flags, named, tmp_path, capsys):
    line = cli_error(["train", "smoke", *flags, "--run-dir", str(tmp_path / "run")], capsys)
    assert named in line and "│" not in line
    assert not (tmp_path / "run").exists()


def test_cli_trains_a_variant_with_flags_over_its_settings(tmp_path, capsys):
    run = tmp_path / "run"
    main(
        [
            "train",
            "smoke",
            "--env",
            NOISY,
            "--extensions.observation-noise-mV",
            "1.5",
            "--params.capacitance-pF",
            "25",
            "--total-env-steps",
            "320",
            "--run-dir",
            str(run),
        ]
    )
    config = read_config(run)
    assert config.env.id == NOISY and config.env.n_neurons == 5  # the preset's size stays
    assert config.env.extensions.observation_noise_mV == 1.5  # the flag beats the variant
    assert config.env.params.capacitance_pF == 25.0
    assert config == Experiment.from_dict(json.loads((run / "config.json").read_text()))
    capsys.readouterr()
    main(["evaluate", str(run)])
    assert "over 6 contexts" in capsys.readouterr().out


@pytest.mark.parametrize("env_flags", [["--env", NOISY], [f"--env={NOISY}"]])
def test_cli_trains_a_variant_on_its_own_settings(env_flags, tmp_path):
    """--env alone takes every setting of the variant (here its 2 mV noise)."""
    run = tmp_path / "run"
    main(["train", "smoke", *env_flags, "--total-env-steps", "320", "--run-dir", str(run)])
    config = read_config(run)
    assert config.env.id == NOISY and config.env.n_neurons == 5
    assert config.env.extensions.observation_noise_mV == 2.0


def test_train_help_shows_the_defaults_it_describes(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    quick = capsys.readouterr().out
    assert "quick preset" in quick and "Table 2 by default" not in quick
    assert "--env" in quick and "--params.v-rest-mV" in quick
    assert "--extensions.observation-noise-mV" in quick
    with pytest.raises(SystemExit):
        main(["train", "paper", "--help"])
    assert "paper preset" in capsys.readouterr().out


def stop_after_first_checkpoint(monkeypatch, config: Experiment, run_dir) -> None:
    """Train ``config`` in ``run_dir`` until its first checkpoint is written, then stop
    as a Ctrl-C would."""
    import spikectl.training.run as run_module

    save = run_module.save_checkpoint

    def save_then_stop(*args, **kwargs):
        save(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(run_module, "save_checkpoint", save_then_stop)
    with pytest.raises(KeyboardInterrupt):
        train(config, run_dir)
    monkeypatch.setattr(run_module, "save_checkpoint", save)


def test_a_noisy_run_resumes_exactly(tmp_path, monkeypatch):
    """The environment's draws are seeded per round, so a run stopped after a checkpoint
    and resumed sees the very noise the uninterrupted run saw."""

    config = SMOKE.with_changes({"env.id": NOISY, "total_env_steps": 4 * 8 * 20,
                                 "eval_every_episodes": 8,
                                 "checkpoint_every_episodes": 16})  # fmt: skip
    whole = train(config, tmp_path / "whole")
    stop_after_first_checkpoint(monkeypatch, config, tmp_path / "stopped")
    resumed = train(config, tmp_path / "stopped", resume=True)

    def comparable(rows):  # NaN (no loss yet) compared as None; clocks left out
        return [{k: None if v != v else v for k, v in row.items() if not k.endswith("time_s")}
                for row in rows]  # fmt: skip

    assert comparable(resumed) == comparable(whole)


def test_a_seed_group_trains_on_the_variant_and_its_seeds_evaluate_alike(tmp_path):
    from spikectl.training.run import train_seeds

    config = SHORT.with_changes({"env.id": NOISY})
    metrics = train_seeds(config, [0, 1], tmp_path / "group")
    for seed, rows in zip((0, 1), metrics, strict=True):
        run = tmp_path / "group" / f"seed={seed}"
        assert read_config(run) == config.with_seed(seed)
        results = {result.name: result.mean for result in evaluate_run(run)}
        assert results["test"] == rows[-1]["test_return"]


def flat_config(config: Experiment) -> dict:
    """The config.json a run got before the tree: one flat dict, the agent's voltage
    normalisation in its sizes."""
    values = config.to_dict()
    env = {k: v for k, v in values["env"].items() if k not in ("id", "params", "extensions")}
    sizes = {**values["agent"]["sizes"], "v_rest_mV": -70.0, "v_threshold_mV": -50.0}
    learner = {k: v for k, v in values["learner"].items() if k != "name"}
    return {**values["train"], **learner, **env, "arch": values["agent"]["arch"],
            "sizes": sizes}  # fmt: skip


def test_a_run_written_before_the_tree_resumes_exactly(tmp_path, monkeypatch):
    from spikectl.training.torch_files import payload_checksum

    config = SMOKE.with_changes(total_env_steps=4 * 8 * 20, eval_every_episodes=8,
                                checkpoint_every_episodes=16)  # fmt: skip
    whole = train(config, tmp_path / "whole")
    run = tmp_path / "old"
    stop_after_first_checkpoint(monkeypatch, config, run)
    # Rewrite its config.json and its checkpoint's config as spikectl wrote them before.
    (run / "config.json").write_text(json.dumps(flat_config(config), indent=2))
    payload = torch.load(run / "checkpoint.pt", weights_only=True)
    del payload["checksum"]
    payload["configs"] = [flat_config(config)]
    payload["checksum"] = payload_checksum(payload)
    torch.save(payload, run / "checkpoint.pt")
    assert read_config(run) == config
    main(["train", "--resume", str(run)])
    assert [row["test_return"] for row in read_metrics(run)] == [
        row["test_return"] for row in whole
    ]
