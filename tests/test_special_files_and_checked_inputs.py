"""Reliability round 3 (issue 26).

Class 1: a FIFO or a link to a device where a file should be is refused in one line,
never read forever (every reader opens through spikectl.files). Class 2: resume and
the environment check what they are given (context sets, params).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from conftest import no_hang

from spikectl.cli import main
from spikectl.contexts import make_splits
from spikectl.contexts.file_format import ContextFileError
from spikectl.experiments.sweep import load_sweep_file
from spikectl.files import NotARegularFileError, open_regular_file, read_text_file
from spikectl.training.presets import SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import RunDirError, read_config, read_metrics
from spikectl.training.torch_files import load_model_weights


def fifo(path: Path) -> Path:
    path.unlink(missing_ok=True)
    os.mkfifo(path)
    return path


def zero_link(path: Path) -> Path:
    path.unlink(missing_ok=True)
    path.symlink_to("/dev/zero")
    return path


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("run") / "run"
    train(SMOKE.with_changes(total_env_steps=2 * 20 * 8, eval_every_episodes=8), run_dir)
    return run_dir


def test_the_readers_refuse_what_is_not_a_regular_file(tmp_path):
    for make, kind in ((fifo, "FIFO"), (zero_link, "character device")):
        path = make(tmp_path / "file")
        with no_hang(), pytest.raises(NotARegularFileError, match=kind):
            read_text_file(path)
        with no_hang(), pytest.raises(NotARegularFileError, match="not a regular file"):
            with open_regular_file(path):
                pass
    regular = tmp_path / "regular.txt"
    regular.write_text("é")
    assert read_text_file(regular) == "é"
    with pytest.raises(ValueError, match="larger than 1 bytes"):
        read_text_file(regular, max_bytes=1)


@pytest.mark.parametrize("make", [fifo, zero_link], ids=["fifo", "dev-zero"])
def test_run_files_that_are_not_files_are_one_line_errors(tmp_path, run_dir, make, capsys):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    for name, read in (("config.json", read_config), ("metrics.csv", read_metrics)):
        saved = (copy / name).read_bytes()
        make(copy / name)
        with no_hang(), pytest.raises(RunDirError, match="not a regular file"):
            read(copy)
        (copy / name).unlink()
        (copy / name).write_bytes(saved)
    make(copy / "model.pt")
    with no_hang(), pytest.raises(RunDirError, match="not a regular file"):
        load_model_weights(copy / "model.pt")
    make(copy / "config.json")
    with no_hang(), pytest.raises(SystemExit) as exit_info:
        main(["evaluate", str(copy)])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "config.json" in line and "not a regular file" in line


def test_context_and_sweep_files_that_are_not_files(tmp_path):
    path = fifo(tmp_path / "contexts.npz")
    from spikectl.contexts import ContextSet

    with no_hang(), pytest.raises(ContextFileError, match="FIFO"):
        ContextSet.load(path)
    with no_hang(), pytest.raises(ValueError, match="not a regular file"):
        load_sweep_file(fifo(tmp_path / "sweep.json"))
    make_splits(2, 2, seed=0)  # the module still works after the refusals


def test_resume_refuses_context_sets_swapped_for_others(tmp_path, interrupt_after_rounds):
    """Issue 26, class 2: a valid context file swapped into a run directory is refused
    on resume, naming the file, and nothing is trained on it."""
    from spikectl.contexts import ContextSet

    config = SMOKE.with_changes(total_env_steps=6 * 20 * 8, eval_every_episodes=16,
                                checkpoint_every_episodes=16)  # fmt: skip
    restore = interrupt_after_rounds(3)  # after the checkpoint at episode 16
    with pytest.raises(KeyboardInterrupt):
        train(config, tmp_path / "run")
    restore()
    path = tmp_path / "run" / "train_contexts.npz"
    original = ContextSet.load(path)
    other = ContextSet.generate(len(original), n_neurons=original.n_neurons,
                                episode_length=original.episode_length, seed=99)  # fmt: skip
    path.unlink()
    other.save(path)
    before = (tmp_path / "run" / "metrics.csv").read_text()
    with pytest.raises(RunDirError, match="train_contexts.npz is not the train set"):
        train(config, tmp_path / "run", resume=True)
    assert (tmp_path / "run" / "metrics.csv").read_text() == before
    path.unlink()
    original.save(path)
    assert train(config, tmp_path / "run", resume=True)[-1]["episode"] == 48


def test_a_closed_pipe_ends_quietly(run_dir):
    """Class 5: ``spikectl evaluate RUN | head -1`` prints no traceback."""
    import subprocess
    import sys

    evaluate = subprocess.Popen(
        [sys.executable, "-m", "spikectl.cli", "evaluate", str(run_dir)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    evaluate.stdout.close()  # the reader is gone before the first line
    stderr = evaluate.stderr.read().decode()
    assert evaluate.wait(timeout=120) == 141
    assert "Traceback" not in stderr and stderr == ""


def test_an_interrupt_is_one_line_with_how_to_resume(monkeypatch, capsys):
    """Class 5: Ctrl-C during a command is one line (exit 130), never a traceback."""
    import spikectl.cli as cli

    def interrupted(command):
        raise KeyboardInterrupt

    monkeypatch.setitem(cli.COMMANDS, "demo", (interrupted, cli.COMMANDS["demo"][1]))
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["demo"])
    assert exit_info.value.code == 130
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "interrupted" in line and "--resume" in line


def test_a_missing_extra_names_the_pip_extra(tmp_path, monkeypatch, capsys):
    """Class 5: ``sweep --backend ray`` without Ray is one line naming the extra."""
    import builtins

    real_import = builtins.__import__

    def no_ray(name, *args, **kwargs):
        if name == "ray":
            raise ImportError("No module named 'ray'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    sweep = tmp_path / "sweep.json"
    sweep.write_text('{"base": "smoke", "overrides": {"total_env_steps": 320}, '
                     '"grid": {"seed": [0]}}')  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", "--config", str(sweep), "--sweep-dir", str(tmp_path / "s"),
              "--backend", "ray", "--workers", "1"])  # fmt: skip
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "pip install 'spikectl[ray]'" in line
    # The refused command leaves no trap: the corrected one runs in the same directory.
    monkeypatch.setattr(builtins, "__import__", real_import)
    main(["sweep", "--config", str(sweep), "--sweep-dir", str(tmp_path / "s"),
          "--backend", "local", "--workers", "1"])  # fmt: skip
    assert (tmp_path / "s" / "trials" / "seed=0" / "model.pt").exists()


def test_two_context_commands_at_once_never_lose_a_result(tmp_path):
    """Class 4: while one ``spikectl contexts --out-dir D`` writes, a second is refused
    naming the first (it used to report success, and one result was lost)."""
    from spikectl.locks import FolderBusyError, folder_lock

    out = tmp_path / "sets"
    with folder_lock(out, "writing context sets"):  # the first command, mid-write
        with pytest.raises(SystemExit) as exit_info:
            main(["contexts", "--out-dir", str(out), "--n-train", "2", "--n-test", "2"])
        assert exit_info.value.code == 2
        with pytest.raises(FolderBusyError, match=f"pid {os.getpid()}"):
            with folder_lock(out, "writing context sets"):
                pass
    assert not (out / "train_contexts.npz").exists()
    main(["contexts", "--out-dir", str(out), "--n-train", "2", "--n-test", "2"])
    assert (out / "train_contexts.npz").exists()


@pytest.mark.parametrize(
    ("body", "problem"),
    [
        (
            '{"base": "smoke", "grid": {"seed": [0]}, "overrides": {"sizes": 4}}',
            "agent.sizes is a section of the config (a table of fields), not a value: got 4",
        ),
        (
            '{"base": {"env": 5}, "grid": {"seed": [0]}}',
            "env is a section of the config (a table of fields), got 5",
        ),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ],
    ids=["number-for-a-table", "number-for-a-section", "deep-json"],
)
def test_sweep_files_of_the_wrong_shape_are_one_line_errors(tmp_path, capsys, body, problem):
    """Class 6: a number where a table belongs, JSON nested too deeply."""
    sweep = tmp_path / "sweep.json"
    sweep.write_text(body)
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", "--config", str(sweep), "--sweep-dir", str(tmp_path / "s")])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert problem in line
    assert not (tmp_path / "s").exists()  # a refused sweep leaves nothing behind


def test_a_run_config_nested_too_deeply_is_a_run_dir_error(tmp_path, run_dir):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    (copy / "config.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(RunDirError, match="nested too deeply"):
        read_config(copy)


def test_sizes_are_checked_before_anything_is_allocated(monkeypatch):
    """Class 7: sizes no machine could hold are refused at once, naming the size."""
    import numpy as np

    import spikectl.files
    from spikectl import simulate
    from spikectl.config_errors import ConfigError
    from spikectl.contexts import Context, ContextSet
    from spikectl.files import TooLargeError
    from spikectl.training.config import TrainConfig

    monkeypatch.setattr(spikectl.files, "physical_memory_bytes", lambda: 2**30)
    weights = np.zeros((8, 8), np.int8)
    with no_hang(), pytest.raises(TooLargeError, match="simulating 1 x 200,000,000 steps"):
        simulate(weights, np.broadcast_to(np.int16(-1), (200_000_000,)))
    with no_hang(), pytest.raises(TooLargeError, match="1,000,000,000,000 contexts"):
        ContextSet.generate(10**12)
    with pytest.raises(ConfigError, match="torch_threads must be an integer in 0..256"):
        TrainConfig(torch_threads=100_000)
    pattern = np.zeros(5, bool)
    pattern[2] = True
    huge = np.zeros((1100, 1100), np.int8)
    with pytest.raises(ValueError, match="n_neurons must be an integer in 2..1024"):
        ContextSet([Context(huge, 1, pattern)])


def test_an_impossible_task_is_one_line_and_leaves_no_trap(tmp_path, capsys):
    """Class 8: params that no target can spike under are a clear error (exit 2), not a
    RuntimeError; class 9: the corrected command then runs in the same directory."""
    run = str(tmp_path / "run")
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "smoke", "--run-dir", run, "--params.synaptic-current-pA", "0",
              "--total-env-steps", "1600"])  # fmt: skip
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "made neuron" in line and "a release moves a neuron by 0 mV" in line
    main(["train", "smoke", "--run-dir", run, "--total-env-steps", "1600"])
    assert (tmp_path / "run" / "model.pt").exists()


def test_absurd_magnitudes_are_refused_where_they_are_given():
    """Class 8: 1e308 pA is refused as a parameter, not reported later as divergence."""
    from spikectl.config_errors import ConfigError
    from spikectl.neuron.params import NeuronParams

    with pytest.raises(ConfigError, match="synaptic_current_pA .* no neuron's"):
        NeuronParams(synaptic_current_pA=1e308)
    with pytest.raises(ConfigError, match="stimulus_current_pA"):
        NeuronParams(stimulus_current_pA=1e12)
    assert NeuronParams(synaptic_current_pA=6000.0).synaptic_step_mV == pytest.approx(200.0)


def test_a_checkpoint_holding_sparse_tensors_is_damaged_not_a_traceback(tmp_path, run_dir):
    """Class 6: a crafted checkpoint with sparse tensors is refused in one line (the
    checksum itself used to raise)."""
    import shutil

    import torch

    from spikectl.training.checkpoint import read_checkpoint

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    payload = torch.load(copy / "checkpoint.pt", weights_only=True)
    network = payload["learners"]["seeds"][0]["network"]
    name = next(key for key, value in network.items() if value.dim() == 2)
    network[name] = network[name].to_sparse()
    torch.save(payload, copy / "checkpoint.pt")
    with pytest.raises(RunDirError, match="is damaged: cannot checksum a torch.sparse_coo"):
        read_checkpoint(copy / "checkpoint.pt")


def test_saving_a_context_set_to_a_folder_is_refused(tmp_path):
    """Class 9: ``ContextSet.save(existing_dir)`` used to write ``existing_dir.npz``
    beside it, where nobody looks."""
    contexts = make_splits(2, 2, seed=0)[0]
    with pytest.raises(ValueError, match="is a folder: give a file name"):
        contexts.save(tmp_path)
    assert not (tmp_path.parent / f"{tmp_path.name}.npz").exists()


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["baselines", "--identify-width", "0"], "--identify-width must be an integer >= 1, got 0"),
        (["baselines", "--oracle-width", "0"], "--oracle-width must be an integer >= 1, got 0"),
        (
            ["train", "smoke", "--extensions.background-rate", "1e30"],
            "--extensions.background-rate must be at most 1000 inputs per neuron per step",
        ),
        (
            ["train", "smoke", "--extensions.background-current-pA", "1e300"],
            "--extensions.background-current-pA must lie in [-1e+06, 1e+06] pA",
        ),
    ],
)
def test_messages_name_the_flag(tmp_path, capsys, argv, line):
    """Class 9 and 8: the message names the flag ("width must be ..." did not), and
    absurd background inputs are refused where they are given ("lam value too large")."""
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--out" if argv[0] == "baselines" else "--run-dir", str(tmp_path / "x")])
    assert exit_info.value.code == 2
    (error,) = capsys.readouterr().err.strip().splitlines()
    assert line in error
    assert not (tmp_path / "x").exists()
