"""The trainer: double-Q target, schedules, replay, determinism, errors, learnability."""

from __future__ import annotations

import errno
import itertools
import json
import math
import re

import numpy as np
import pytest
import torch

from spikectl import ContextSet
from spikectl.agents import AgentSizes
from spikectl.files import FileWriteError, atomic_write_bytes
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.training.config import EnvConfig, Experiment
from spikectl.training.learners.dqn import td_loss
from spikectl.training.presets import PRESETS, QUICK, SMOKE
from spikectl.training.replay import EpisodeBatchArrays, EpisodeReplay
from spikectl.training.run import train
from spikectl.training.run_files import RunDirError, read_metrics


class TableQ(torch.nn.Module):
    """A stand-in network whose Q-values are a fixed table indexed by the step."""

    def __init__(self, table: list[list[float]]) -> None:
        super().__init__()
        self.table = torch.nn.Parameter(torch.tensor(table, dtype=torch.float32))  # [N+1, A]

    def forward(self, obs_seq, state=None):
        q_values = self.table[obs_seq["step"]]  # [B, T, A]
        return q_values, state


def test_double_q_target_on_a_hand_computed_two_step_episode():
    # n = 2 neurons, target 1, so the legal actions are -1 and 0 (indices 0, 1); index 2
    # (stimulate the target) is illegal. N = 2 steps; observations 0, 1, 2.
    online = TableQ([[0.1, 0.4, 0.0], [0.2, 0.3, 9.0], [0.0, 0.0, 0.0]])
    target = TableQ([[0.0, 0.0, 0.0], [0.7, 0.5, 5.0], [1.0, 1.0, 1.0]])
    batch = EpisodeBatchArrays(
        voltage=np.full((1, 3, 2), -70.0, dtype=np.float32),
        actions=np.array([[0, -1]]),
        rewards=np.array([[0.25, 0.5]], dtype=np.float32),
        targets=np.array([1]),
        patterns=np.array([[0, 1]], dtype=np.int8),
        action_masks=np.array([[True, True, False]]),
    )
    config = SMOKE.with_changes(gamma=0.9, n_neurons=2, episode_length=2)
    loss = td_loss(online, target, batch, config.learner)
    # Step 0 took action 0 (index 1): Q = 0.4. The online net's best legal action at
    # observation 1 is index 1 (0.3 > 0.2; the illegal 9.0 is masked), which the target
    # net values at 0.5 (not its own max, 0.7): y0 = 0.25 + 0.9 * 0.5 = 0.7.
    # Step 1 took do-nothing (index 0): Q = 0.2, terminal: y1 = 0.5.
    expected = ((0.4 - 0.7) ** 2 + (0.2 - 0.5) ** 2) / 2
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    huber = td_loss(online, target, batch, config.with_changes(loss="huber").learner)
    assert huber.item() == pytest.approx(0.5 * ((0.3) ** 2 + (0.3) ** 2) / 2, rel=1e-6)
    loss.backward()  # gradients reach the online table only through the taken actions
    assert online.table.grad[1, 2] == 0 and online.table.grad[0, 1] != 0
    assert target.table.grad is None


def test_epsilon_schedule():
    config = SMOKE.with_changes(epsilon_start=1.0, epsilon_end=0.1)
    total = config.total_episodes
    anneal = 0.25 * total
    epsilon = config.learner.epsilon
    assert epsilon(0, total) == 1.0
    assert epsilon(anneal / 2, total) == pytest.approx(0.55)
    assert epsilon(anneal, total) == pytest.approx(0.1)
    assert epsilon(total, total) == pytest.approx(0.1)
    assert config.with_changes(epsilon_anneal_fraction=0.0).learner.epsilon(0, total) == 0.1


def make_episodes(count: int, marker_start: int, n: int = 3, length: int = 4):
    voltage = np.zeros((count, length + 1, n), dtype=np.float32)
    voltage[:, 0, 0] = np.arange(marker_start, marker_start + count)  # identifies the episode
    return (
        voltage,
        np.zeros((count, length), dtype=np.int64),
        np.zeros((count, length), dtype=np.float32),
        np.zeros(count, dtype=np.int64),
        np.zeros((count, length), dtype=np.int8),
        np.ones((count, n + 1), dtype=bool),
    )


def test_replay_samples_whole_episodes_uniformly():
    replay = EpisodeReplay(capacity=10, n_neurons=3, episode_length=4)
    replay.add(*make_episodes(10, 0))
    draws = 20_000
    sample = replay.sample(draws, np.random.default_rng(0))
    counts = np.bincount(sample.voltage[:, 0, 0].astype(int), minlength=10)
    expected = draws / 10
    assert np.all(np.abs(counts - expected) < 4 * np.sqrt(expected * 0.9))
    chi_square = ((counts - expected) ** 2 / expected).sum()
    assert chi_square < 27.9  # p = 0.001 for 9 degrees of freedom


def test_replay_is_a_ring_and_round_trips():
    replay = EpisodeReplay(capacity=4, n_neurons=3, episode_length=4)
    replay.add(*make_episodes(3, 0))
    replay.add(*make_episodes(3, 100))  # overwrites the two oldest
    assert len(replay) == 4
    assert sorted(replay.voltage[:, 0, 0].tolist()) == [2, 100, 101, 102]
    restored = EpisodeReplay(capacity=4, n_neurons=3, episode_length=4)
    restored.load_state_dict(replay.state_dict())
    rng_a, rng_b = np.random.default_rng(1), np.random.default_rng(1)
    np.testing.assert_array_equal(
        replay.sample(8, rng_a).voltage, restored.sample(8, rng_b).voltage
    )
    restored.add(*make_episodes(1, 200))
    replay.add(*make_episodes(1, 200))
    np.testing.assert_array_equal(replay.voltage, restored.voltage)
    with pytest.raises(ValueError, match="empty"):
        EpisodeReplay(2, 3, 4).sample(1, rng_a)


def test_two_runs_with_one_seed_are_bit_identical(tmp_path, comparable, assert_same_weights):
    first = train(SMOKE, tmp_path / "a")
    second = train(SMOKE, tmp_path / "b")
    assert comparable(first) == comparable(second)
    assert_same_weights(tmp_path / "a" / "model.pt", tmp_path / "b" / "model.pt")
    other = train(SMOKE.with_changes(seed=1), tmp_path / "c")
    assert comparable(other) != comparable(first)
    rows = read_metrics(tmp_path / "a")
    assert [row["episode"] for row in rows] == [0, 80, 160, 240, 320]
    assert rows[-1]["env_steps"] == SMOKE.total_episodes * SMOKE.env.episode_length
    assert math.isnan(rows[0]["loss"]) and rows[-1]["loss"] > 0
    # The evaluation clock: zero before the first evaluation, then growing, and a part
    # of the run's core-seconds.
    evaluating = [row["eval_cpu_time_s"] for row in rows]
    assert evaluating[0] == 0.0 and all(b > a for a, b in itertools.pairwise(evaluating))
    assert all(row["eval_cpu_time_s"] < row["cpu_time_s"] for row in rows[1:])
    for name in ("config.json", "baselines.json", "checkpoint.pt", "train_contexts.npz",
                 "test_contexts.npz", "tensorboard"):  # fmt: skip
        assert (tmp_path / "a" / name).exists(), name
    baselines = json.loads((tmp_path / "a" / "baselines.json").read_text())
    assert baselines["do_nothing"]["train"] == pytest.approx(0.5, abs=1e-12)


def test_a_run_dir_holding_another_run_is_refused(tmp_path):
    train(SMOKE.with_changes(total_env_steps=8 * 20), tmp_path / "run")
    with pytest.raises(RunDirError, match="already holds a run"):
        train(SMOKE, tmp_path / "run")
    with pytest.raises(RunDirError, match="does not match"):
        train(SMOKE.with_changes(seed=5), tmp_path / "run", resume=True)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(RunDirError, match="not empty"):
        train(SMOKE, tmp_path / "other")
    with pytest.raises(RunDirError, match="no run to resume"):
        train(SMOKE, tmp_path / "nothing", resume=True)


def test_incompatible_checkpoint_is_refused(tmp_path):
    run = tmp_path / "run"
    train(SMOKE.with_changes(total_env_steps=8 * 20), run)
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=False)
    checkpoint["format_version"] = 99
    torch.save(checkpoint, run / "checkpoint.pt")
    config = SMOKE.with_changes(total_env_steps=8 * 20)
    with pytest.raises(RunDirError, match="format 99"):
        train(config, run, resume=True)
    (run / "checkpoint.pt").write_bytes(b"garbage")
    with pytest.raises(RunDirError, match="not a readable spikectl checkpoint"):
        train(config, run, resume=True)


def test_full_disk_is_a_clear_error_and_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "file.bin"
    atomic_write_bytes(path, b"old")

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("os.replace", no_space)
    with pytest.raises(FileWriteError, match="no space left.*previous version.*intact"):
        atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["file.bin"]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("total_env_steps", 0, "total_env_steps"),
        ("gamma", 1.5, "gamma"),
        ("tau", 0.0, "tau"),
        ("learning_rate", -1.0, "learning_rate"),
        ("epsilon_end", 2.0, "epsilon_end"),
        ("loss", "l1", "loss"),
        ("arch", "lstm", "arch"),
        ("batch_size", 10**6, "batch_size"),
        ("num_envs", 0, "num_envs"),
    ],
)
def test_bad_config_values(field, value, message):
    with pytest.raises(ValueError, match=message):
        SMOKE.with_changes(**{field: value})


def test_config_round_trips_through_json():
    for preset in PRESETS.values():
        assert Experiment.from_dict(json.loads(json.dumps(preset.to_dict()))) == preset
    noisy = SMOKE.with_changes({"env.id": "spikectl/NeuronControlNoisy-v0",
                                "env.params.capacitance_pF": 25.0})  # fmt: skip
    assert Experiment.from_dict(json.loads(json.dumps(noisy.to_dict()))) == noisy
    with pytest.raises(ValueError, match="unknown TrainConfig field"):
        Experiment.from_dict({"train": {"learning_rat": 1e-3}})
    with pytest.raises(ValueError, match="unknown config field 'learning_rat'"):
        Experiment.from_dict({"learning_rat": 1e-3})
    with pytest.raises(ValueError, match="unknown NeuronParams field"):
        Experiment.from_dict({"env": {"params": {"v_rest": -65.0}}})


def test_a_config_before_the_tree_loads_into_it():
    """config.json of runs written before the tree: flat fields, the agent's voltage
    normalisation in its sizes, no n_val."""
    flat = {**SMOKE.train.__dict__, **SMOKE.learner.__dict__, "arch": "drqn",
            "n_neurons": 5, "episode_length": 20,
            "n_train": 6, "n_test": 6, "context_seed": 0, "train_contexts": None,
            "test_contexts": None,
            "sizes": {**SMOKE.with_changes().to_dict()["agent"]["sizes"],
                      "v_rest_mV": -70.0, "v_threshold_mV": -50.0}}  # fmt: skip
    loaded = Experiment.from_dict(flat)
    assert loaded == SMOKE.with_changes(arch="drqn", n_val=0)
    with pytest.raises(ValueError, match="sizes.v_rest_mV = -65.0 differs from"):
        Experiment.from_dict({**flat, "sizes": {"v_rest_mV": -65.0}})


def test_changes_name_fields_by_path_nested_or_flat():
    by_path = QUICK.with_changes({"env.n_train": 20, "agent.sizes.lstm_hidden": 32})
    nested = QUICK.with_changes({"env": {"n_train": 20}, "agent": {"sizes": {"lstm_hidden": 32}}})
    flat = QUICK.with_changes(n_train=20, sizes={"lstm_hidden": 32})
    assert by_path == nested == flat
    assert flat.env.n_train == 20 and flat.agent.sizes.lstm_hidden == 32
    assert flat.agent.sizes.attn_width == QUICK.agent.sizes.attn_width  # the rest stays
    # A variant's settings come first, then the changes given with it.
    noisy = SMOKE.with_changes({"env.id": "spikectl/NeuronControlNoisy-v0"})
    assert noisy.env.extensions.observation_noise_mV == 2.0 and noisy.env.n_neurons == 5
    quiet = SMOKE.with_changes({"env.id": "spikectl/NeuronControlNoisy-v0",
                                "env.extensions.observation_noise_mV": 0.5})  # fmt: skip
    assert quiet.env.extensions.observation_noise_mV == 0.5
    assert noisy.with_changes({"env.id": "spikectl/NeuronControl-v0"}) == SMOKE
    big = SMOKE.with_changes({"env.id": "spikectl/NeuronControl32-v0"})
    assert big.env.n_neurons == 32 and big.env.extensions == Extensions()
    # The id alone would record a variant the run does not train on: refused.
    with pytest.raises(ValueError, match="sets extensions.observation_noise_mV = 2.0, but"):
        EnvConfig(id="spikectl/NeuronControlNoisy-v0")
    assert EnvConfig().with_variant("spikectl/NeuronControlNoisy-v0").extensions == Extensions(
        observation_noise_mV=2.0
    )
    with pytest.raises(ValueError, match="unknown environment id 'spikectl/Nope-v0'"):
        SMOKE.with_changes({"env.id": "spikectl/Nope-v0"})
    with pytest.raises(ValueError, match="not a spikectl environment"):
        SMOKE.with_changes({"env.id": "CartPole-v1"})


def test_paper_preset_is_table_2():
    paper = PRESETS["paper"]
    assert (paper.train.total_env_steps, paper.env.episode_length, paper.learner.buffer_size) == (
        1_000_000,
        60,
        16_667,
    )
    algorithm = paper.learner
    assert (algorithm.batch_size, algorithm.updates_per_round, algorithm.gamma,
            algorithm.tau) == (5, 10, 0.99, 0.1)  # fmt: skip
    assert (algorithm.epsilon_start, algorithm.epsilon_end,
            algorithm.epsilon_anneal_fraction) == (1.0, 0.05, 0.25)  # fmt: skip
    # The paper's environment and Table 2's networks: every default of the tree.
    assert paper == Experiment() and paper.env == EnvConfig() and paper.agent.sizes == AgentSizes()
    assert paper.env.params == NeuronParams() and paper.env.extensions == Extensions()
    assert paper.learner.learning_rate == 5e-4 and paper.agent.sizes.lstm_hidden == 128
    assert paper.total_episodes == 16_665  # whole rounds of 5 episodes


def test_learnability_on_one_easy_network(tmp_path, easy_network_config):
    """One network, short episodes: a smoke-sized run clearly beats doing nothing."""
    metrics = train(easy_network_config, tmp_path / "run")
    assert metrics[0]["train_return"] < 0.75
    assert metrics[-1]["train_return"] > 0.9


LEARN_FAST_FLAGS = ("--n-step", "3", "--aux-voltage-weight", "1.0", "--explore-do-nothing",
                    "0.75", "--learning-rate-end-fraction", "0.1",
                    "--sizes.inputs", "target", "target-voltage")  # fmt: skip


# Slow tier (26 and 38 CPU s): three smoke runs each. An exact resume from a checkpoint
# stays in the default tier (test_learner_protocol, test_ensemble's stacked group).
@pytest.mark.slow
@pytest.mark.parametrize(
    "flags",
    [(), LEARN_FAST_FLAGS],
    ids=["paper", "learn-fast"],
)
def test_resume_after_sigkill_is_exact(
    tmp_path, flags, comparable, assert_same_weights, run_cli, wait_until
):
    """Kill a run with SIGKILL after a checkpoint, resume it: the same metrics.csv rows and
    bit-identical final weights as an uninterrupted run (also with the auxiliary head,
    n-step targets and biased exploration of the quick preset).

    The kill comes once the run has checkpointed (episode 80) and written its evaluation
    at episode 160, just before or after its second checkpoint: polling for that
    progress, not a fixed sleep that a busy machine makes too short or too long."""
    import os
    import signal
    import subprocess
    import sys

    reference = tmp_path / "reference"
    run_cli("train", "smoke", *flags, "--run-dir", str(reference))
    killed = tmp_path / "killed"
    process = subprocess.Popen(
        [sys.executable, "-m", "spikectl.cli", "train", "smoke", *flags,
         "--run-dir", str(killed)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    metrics = killed / "metrics.csv"
    # Rows for episodes 0, 80 and 160 under the header; checkpoint.pt from episode 80 on.
    wait_until(
        lambda: (killed / "checkpoint.pt").exists() and metrics.exists()
        and len(metrics.read_text().splitlines()) >= 4,
        "the second evaluation", timeout_s=120, process=process,
    )  # fmt: skip
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert not (killed / "model.pt").exists(), "killed too late to test anything"
    resumed = run_cli("train", "--resume", str(killed))
    assert "train" in resumed.stdout
    assert comparable(read_metrics(killed)) == comparable(read_metrics(reference))
    assert_same_weights(killed / "model.pt", reference / "model.pt")
    assert_same_weights(killed / "best_model.pt", reference / "best_model.pt")


@pytest.mark.slow  # three smoke trainings (about 28 CPU s); the other SIGTERM tests stay fast
def test_sigterm_checkpoints_says_so_and_the_resume_is_exact(
    tmp_path, comparable, assert_same_weights, run_cli, wait_until
):
    """SIGTERM (what Slurm and Docker send) during ``spikectl train``, a real process
    started as the installed command is: the round under way finishes, a checkpoint of
    it is written, one line says where, the exit status is 143 (128 + 15); ``--resume``
    then gives the rows and weights of a run never stopped. Its only mid-run checkpoint
    is SIGTERM's (the scheduled one is at the end)."""
    import re
    import signal
    import subprocess
    import sys

    flags = ("--checkpoint-every-episodes", "320")
    reference = tmp_path / "reference"
    run_cli("train", "smoke", *flags, "--run-dir", str(reference))
    stopped = tmp_path / "stopped"
    process = subprocess.Popen(
        [sys.executable, "-m", "_spikectl_launcher", "train", "smoke", *flags,
         "--run-dir", str(stopped)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    metrics = stopped / "metrics.csv"
    wait_until(
        lambda: metrics.exists() and len(metrics.read_text().splitlines()) >= 3,
        "the evaluation at episode 80", timeout_s=120, process=process,
    )  # fmt: skip
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 143, err
    (line,) = err.strip().splitlines()
    found = re.fullmatch(
        rf"spikectl: terminated \(SIGTERM\): checkpoint written at episode (\d+) in "
        rf"{re.escape(str(stopped))}; continue with spikectl train --resume "
        rf"{re.escape(str(stopped))}", line,
    )  # fmt: skip
    assert found, line
    # The round under way when the signal lands: the one ending at episode 80 itself when
    # SIGTERM arrives between that evaluation's row and the round's end.
    assert 80 <= int(found.group(1)) < 320, "stopped too late to test anything"
    assert (stopped / "checkpoint.pt").exists() and not (stopped / "model.pt").exists()
    run_cli("train", "--resume", str(stopped))
    assert comparable(read_metrics(stopped)) == comparable(read_metrics(reference))
    assert_same_weights(stopped / "model.pt", reference / "model.pt")
    assert_same_weights(stopped / "best_model.pt", reference / "best_model.pt")


def test_sigterm_outside_training_ends_a_command_in_one_line(monkeypatch, capsys):
    """Any other command ends on SIGTERM as on a Ctrl-C: one line, exit 143 (it was the
    signal's silent kill, -15). In this process: the command sends itself SIGTERM."""
    import os
    import signal
    import time

    import spikectl.cli as cli

    def terminated_while_running(command):
        # Without spikectl's handler SIGTERM would end the test run itself: fail instead.
        assert signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL, "SIGTERM not handled"
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(10)
        raise AssertionError("SIGTERM did not end the command")

    monkeypatch.setitem(cli.COMMANDS, "demo", (terminated_while_running, cli.DemoConfig))
    with pytest.raises(SystemExit) as exit:
        cli.main(["demo"])
    assert exit.value.code == 143
    assert capsys.readouterr().err.strip().splitlines() == [
        "spikectl: terminated (SIGTERM) (a training run or sweep continues from its last "
        "checkpoint: spikectl train --resume RUN_DIR, or the same sweep command)"
    ]
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored after the command


def test_evaluate_reproduces_the_last_evaluation_exactly(tmp_path):
    """evaluate_run scores as training did: the same networks, the same greedy episodes,
    on the run's own thread count whatever the caller's (then restored)."""
    from spikectl.training.evaluate import evaluate_run

    config = SMOKE.with_changes(n_val=3)
    train(config, tmp_path / "run")
    final = read_metrics(tmp_path / "run")[-1]
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        results = {result.name: result.mean for result in evaluate_run(tmp_path / "run")}
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert results == {"train": final["train_return"], "test": final["test_return"],
                       "validation": final["val_return"]}  # fmt: skip


def test_cli_train_then_evaluate(tmp_path, run_cli):
    run = tmp_path / "run"
    out = run_cli("train", "smoke", "--arch", "ddrqn", "--total-env-steps", "1600",
                  "--run-dir", str(run))  # fmt: skip
    assert "do-nothing" in out.stdout and (run / "learning_curve.png").exists()
    assert re.search(r"core minutes, \d+\.\d of them evaluating\)", out.stdout), out.stdout
    evaluated = run_cli("evaluate", str(run)).stdout
    assert "train" in evaluated and "test" in evaluated and "do nothing 0.500" in evaluated
    # Evaluate on a set the user brings: a per-neuron agent runs on 7-neuron networks.
    other = ContextSet.generate(4, n_neurons=7, episode_length=20, seed=3)
    other.save(tmp_path / "mine.npz")
    assert (
        "over 4 contexts"
        in run_cli("evaluate", str(run), "--contexts", str(tmp_path / "mine.npz")).stdout
    )
    again = run_cli("train", "smoke", "--run-dir", str(run), check=False)
    assert again.returncode == 2 and "already holds a run" in again.stderr


def test_a_second_sigterm_while_the_round_finishes_stops_at_once():
    import os
    import signal

    from spikectl.training.termination import Terminated, deferred_termination

    with deferred_termination() as requested:
        assert not requested()
        os.kill(os.getpid(), signal.SIGTERM)  # recorded, nothing raised
        assert requested()
        with pytest.raises(Terminated):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs between bytecodes
                pass
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
