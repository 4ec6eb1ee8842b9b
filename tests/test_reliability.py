"""Hostile but realistic use: bad inputs, damaged and crafted files, full disks, kills.

Every case gets one clear error (one line and exit status 2 on the command line) that
names the argument or the file, never a traceback, a silently wrong result, a hang,
lost data or code run from a file. docs/reliability.md counts the cases by class.
"""

from __future__ import annotations

import errno
import io
import json
import math
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import spikectl  # noqa: F401  (registers the environments)
from spikectl import ContextSet, NeuronParams
from spikectl.cli import main
from spikectl.contexts.file_format import ContextFileError
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.experiments.backends import Backend
from spikectl.experiments.sweep import Sweep, SweepError, run_sweep, run_trial
from spikectl.files import FileWriteError
from spikectl.training.checkpoint import read_checkpoint
from spikectl.training.config import EnvConfig
from spikectl.training.presets import SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import CLOCK_FIELDS, RunDirError, run_lock
from spikectl.training.torch_files import load_model_weights, payload_checksum, save_model

TINY = SMOKE.with_changes(
    total_env_steps=8 * 20 * 2, checkpoint_every_episodes=8, eval_every_episodes=8
)
TINY_FLAGS = ["smoke", "--total-env-steps", "320", "--checkpoint-every-episodes",
              "8", "--eval-every-episodes", "8"]  # fmt: skip


class Payload:
    """Unpickling this writes a marker file: proof that a file ran code."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "code ran"))


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("finished") / "run"
    train(TINY, run)
    return run


@pytest.fixture
def run_copy(finished_run, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(finished_run, copy)
    return copy


def cli_error(argv: list[str], capsys) -> str:
    """Run the CLI expecting a user error: exit status 2 and exactly one stderr line."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("spikectl: error: ") and "Traceback" not in lines[0]
    return lines[0]


def flip_tensor_byte(path: Path) -> None:
    """Flip one bit in the middle of the largest tensor record of a torch zip file."""
    with zipfile.ZipFile(path) as archive:
        info = max((i for i in archive.infolist() if "/data/" in i.filename),
                   key=lambda i: i.file_size)  # fmt: skip
    data = bytearray(path.read_bytes())
    name_length, extra_length = struct.unpack("<HH", data[info.header_offset + 26 :][:4])
    start = info.header_offset + 30 + name_length + extra_length
    data[start + info.file_size // 2] ^= 0x40
    path.write_bytes(bytes(data))


def absurd_torch_file(path: Path) -> None:
    """A torch file whose tensor claims 2**40 elements over a record of 13."""
    torch.save({"w": torch.zeros(13)}, path)
    with zipfile.ZipFile(path) as archive:
        members = [(info.filename, archive.read(info)) for info in archive.infolist()]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as archive:
        for name, data in members:
            if name.endswith("data.pkl"):
                data = data.replace(b"K\x0d", b"\x8a\x06" + (2**40).to_bytes(6, "little"))
            archive.writestr(name, data)


def damage(path: Path, kind: str, marker: Path) -> None:
    """Replace a file of a run by one of the damaged, foreign or crafted kinds."""
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "truncated":
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    elif kind == "foreign":
        path.write_text("these are my notes, not a spikectl file\n")
    elif kind == "directory":
        path.unlink()
        path.mkdir()
    elif kind == "flipped":
        flip_tensor_byte(path)
    elif kind == "crafted":
        torch.save({"format": "spikectl.checkpoint", "online": Payload(marker)}, path)
    elif kind == "absurd":
        absurd_torch_file(path)
    elif kind == "other-torch":
        torch.save({"weights": torch.ones(3)}, path)
    else:
        raise AssertionError(kind)


TORCH_DAMAGE = ["empty", "truncated", "foreign", "directory", "flipped", "crafted", "absurd",
                "other-torch"]  # fmt: skip


# --- Safe loading and damage detection: checkpoint.pt and model.pt ----------------------


@pytest.mark.parametrize("kind", TORCH_DAMAGE)
def test_damaged_or_crafted_checkpoint_is_refused_by_train_resume(run_copy, kind, tmp_path,
                                                                  capsys):  # fmt: skip
    (run_copy / "model.pt").unlink()  # an interrupted run
    marker = tmp_path / "marker"
    damage(run_copy / "checkpoint.pt", kind, marker)
    line = cli_error(["train", "--resume", str(run_copy)], capsys)
    assert "checkpoint.pt" in line
    assert not marker.exists(), "a file ran code"
    assert not (run_copy / "model.pt").exists()


@pytest.mark.parametrize("kind", TORCH_DAMAGE)
def test_damaged_or_crafted_model_is_refused_by_evaluate(run_copy, kind, tmp_path, capsys):
    marker = tmp_path / "marker"
    damage(run_copy / "model.pt", kind, marker)
    line = cli_error(["evaluate", str(run_copy)], capsys)
    assert "model.pt" in line
    assert not marker.exists(), "a file ran code"


@pytest.mark.parametrize("kind", ["flipped", "crafted", "truncated"])
def test_evaluate_falls_back_to_a_checked_checkpoint(run_copy, kind, tmp_path, capsys):
    (run_copy / "model.pt").unlink()
    main(["evaluate", str(run_copy)])  # the intact checkpoint serves
    assert "train" in capsys.readouterr().out
    marker = tmp_path / "marker"
    damage(run_copy / "checkpoint.pt", kind, marker)
    assert "checkpoint.pt" in cli_error(["evaluate", str(run_copy)], capsys)
    assert not marker.exists()


def test_a_rerun_sweep_refuses_a_crafted_checkpoint(run_copy, tmp_path):
    (run_copy / "model.pt").unlink()
    marker = tmp_path / "marker"
    damage(run_copy / "checkpoint.pt", "crafted", marker)
    with pytest.raises(RunDirError, match="could run code"):
        run_trial(TINY, run_copy)
    assert not marker.exists()
    damage(run_copy / "checkpoint.pt", "directory", marker)
    with pytest.raises(RunDirError, match="folder"):
        run_trial(TINY, run_copy)


def test_a_sweep_reports_a_damaged_trial_in_one_line(finished_run, tmp_path, capsys):
    sweep = Sweep(base=TINY, grid={"seed": [0]})
    trial = tmp_path / "sweep" / "trials" / "seed=0"
    shutil.copytree(finished_run, trial)
    flip_tensor_byte(trial / "model.pt")
    with pytest.raises(Exception, match="1 of 1 trial.*model.pt is damaged"):
        run_sweep(sweep, tmp_path / "sweep", Backend(workers=1), echo=lambda line: None)


@pytest.mark.slow
def test_a_ray_sweep_reports_a_damaged_trial_in_one_line(finished_run, tmp_path, capsys):
    pytest.importorskip("ray")
    sweep = Sweep(base=TINY, grid={"seed": [0, 1]})
    trial = tmp_path / "sweep" / "trials" / "seed=0"
    shutil.copytree(finished_run, trial)
    flip_tensor_byte(trial / "model.pt")
    with pytest.raises(SweepError, match=r"1 of 2 trial.*seed=0.*model.pt is damaged"):
        run_sweep(sweep, tmp_path / "sweep", Backend("ray", workers=2), echo=lambda line: None)
    # The healthy trial finished and is usable.
    assert load_model_weights(tmp_path / "sweep" / "trials" / "seed=1" / "model.pt")
    with pytest.raises(SystemExit) as exit_info:  # and on the command line: one line, exit 2
        main(["sweep", "--config", str(write_sweep_file(tmp_path, sweep)), "--backend", "ray",
              "--workers", "2", "--sweep-dir", str(tmp_path / "sweep")])  # fmt: skip
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-1].startswith("spikectl: error: 1 of 2 trial(s) failed")


def write_sweep_file(folder: Path, sweep: Sweep) -> Path:
    path = folder / "sweep-file.json"
    path.write_text(json.dumps(sweep.to_dict()))
    return path


def test_model_files_are_plain_state_dicts_with_a_checksum(finished_run):
    weights = torch.load(finished_run / "model.pt", weights_only=True)
    header = weights._metadata["spikectl"]
    assert header["format"] == "spikectl.model" and header["checksum"] == payload_checksum(
        dict(weights)
    )
    from spikectl.training.loaders import load_agent

    network = load_agent(finished_run)
    network.load_state_dict(weights)  # strict: the metadata entry is not a weight


def test_checkpoint_loads_weights_only_and_an_old_format_is_named(finished_run, tmp_path):
    payload = torch.load(finished_run / "checkpoint.pt", weights_only=True)
    assert payload["format_version"] == 3 and len(payload["checksum"]) == 64
    old = dict(payload, format_version=1, replay={"voltage": np.zeros(3)})
    torch.save(old, tmp_path / "checkpoint.pt")
    with pytest.raises(RunDirError, match="checkpoint format 1 .*reads formats 2 and 3"):
        read_checkpoint(tmp_path / "checkpoint.pt")


@pytest.mark.parametrize("key", ["learners", "runs", "configs", "checksum", "rng", "episodes"])
def test_a_checkpoint_missing_a_key_is_refused(finished_run, tmp_path, key):
    from spikectl.training.torch_files import payload_checksum

    payload = torch.load(finished_run / "checkpoint.pt", weights_only=True)
    if key in payload:
        del payload[key]
    else:  # an entry of the run's state: the file stays self-consistent otherwise
        del payload["runs"][0][key]
        payload.pop("checksum")
        payload["checksum"] = payload_checksum(payload)
    torch.save(payload, tmp_path / "checkpoint.pt")
    with pytest.raises(RunDirError, match=f"no '{key}' entry"):
        read_checkpoint(tmp_path / "checkpoint.pt")


def test_a_model_with_nan_weights_is_refused(run_copy, capsys):
    network = torch.nn.Linear(2, 2)
    with torch.no_grad():
        network.weight[0, 0] = math.nan
    with pytest.raises(RunDirError, match="NaN"):
        save_model(run_copy, network)
    weights = torch.load(run_copy / "model.pt", weights_only=True)
    name = next(iter(weights))
    weights[name].view(-1)[0] = math.nan
    weights._metadata["spikectl"]["checksum"] = payload_checksum(dict(weights))
    torch.save(weights, run_copy / "model.pt")  # a consistent file of NaN weights
    with pytest.raises(RunDirError, match="NaN or infinite"):
        load_model_weights(run_copy / "model.pt")
    assert "NaN" in cli_error(["evaluate", str(run_copy)], capsys)


# --- Context files --------------------------------------------------------------------


def npz_damage(path: Path, kind: str) -> None:
    if kind in ("empty", "truncated", "foreign", "directory"):
        damage(path, kind, path)
    elif kind == "flipped":
        arrays = dict(np.load(path))
        arrays["targets"] = (arrays["targets"] + 1) % 5
        np.savez_compressed(path, **arrays)
    elif kind == "missing-key":
        arrays = dict(np.load(path))
        del arrays["witnesses"]
        np.savez_compressed(path, **arrays)
    elif kind == "absurd":
        with zipfile.ZipFile(path) as archive:
            members = [(info.filename, archive.read(info)) for info in archive.infolist()]
        with zipfile.ZipFile(path, "w") as archive:
            for name, data in members:
                if name == "weights.npy":  # the header claims 1.5 TB, the data stay small
                    header = io.BytesIO()
                    np.lib.format.write_array_header_1_0(
                        header, {"descr": "|i1", "fortran_order": False,
                                 "shape": (6, 500_000, 500_000)},
                    )  # fmt: skip
                    data = header.getvalue() + data[data.index(b"\n") + 1 :]
                archive.writestr(name, data)
    elif kind == "pickled":
        np.savez(path, metadata=np.array([{"format": "x"}], dtype=object))
    else:
        raise AssertionError(kind)


NPZ_DAMAGE = ["empty", "truncated", "foreign", "directory", "flipped", "missing-key", "absurd",
              "pickled"]  # fmt: skip


@pytest.mark.parametrize("kind", NPZ_DAMAGE)
def test_damaged_context_files_are_one_clear_error_everywhere(run_copy, kind, tmp_path, capsys):
    path = tmp_path / "set.npz"
    shutil.copy(run_copy / "train_contexts.npz", path)
    npz_damage(path, kind)
    with pytest.raises(ContextFileError, match="set.npz"):
        ContextSet.load(path)
    line = cli_error(["train", *TINY_FLAGS, "--train-contexts", str(path), "--run-dir",
                      str(tmp_path / "new")], capsys)  # fmt: skip
    assert "set.npz" in line
    assert "set.npz" in cli_error(["evaluate", str(run_copy), "--contexts", str(path)], capsys)
    npz_damage(run_copy / "test_contexts.npz", kind)
    assert "test_contexts.npz" in cli_error(["evaluate", str(run_copy)], capsys)


# --- No silent nonsense ---------------------------------------------------------------


def test_a_nan_loss_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path, monkeypatch):
    import spikectl.training.learners.dqn as dqn

    real_losses = dqn.training_losses
    calls = []

    def loss_that_diverges(*args):
        calls.append(1)
        td, aux = real_losses(*args)
        return (td * math.nan if len(calls) > 2 else td), aux

    monkeypatch.setattr(dqn, "training_losses", loss_that_diverges)
    run = tmp_path / "run"
    with pytest.raises(RunDirError, match="training loss became nan.*diverged"):
        train(TINY.with_changes(total_env_steps=8 * 20 * 4), run)
    assert not (run / "model.pt").exists()
    payload = read_checkpoint(run / "checkpoint.pt")  # the last good one, intact
    (learner,) = payload["learners"]["seeds"]
    assert learner["updates"] == 2
    assert all(torch.isfinite(t).all() for t in learner["network"].values())


def test_a_run_without_updates_says_so(tmp_path, capsys):
    with pytest.warns(RuntimeWarning, match="no gradient update"):
        train(TINY.with_changes(learning_starts=10_000, buffer_size=10_000),
              tmp_path / "api")  # fmt: skip
    main(["train", *TINY_FLAGS, "--updates-per-round", "0", "--run-dir", str(tmp_path / "cli")])
    assert "warning: the run" in capsys.readouterr().err


def test_neuron_parameters_are_range_checked():
    with pytest.raises(ValueError, match="refractory_steps must be an integer in 0.."):
        NeuronParams(refractory_steps=2**31)
    with pytest.raises(ValueError, match="threshold_tolerance_mV.*resting neurons spike"):
        NeuronParams(threshold_tolerance_mV=20.0)
    params = NeuronParams(refractory_steps=np.int64(2), capacitance_pF=np.float32(30.0))
    assert type(params.refractory_steps) is int and type(params.capacitance_pF) is float
    assert json.loads(json.dumps(params.to_dict())) == params.to_dict()
    assert params == NeuronParams(refractory_steps=2)


def test_network_size_is_limited_before_anything_is_allocated():
    from spikectl.contexts import MAX_N_NEURONS

    for call in (
        lambda: ContextSet.generate(1, n_neurons=MAX_N_NEURONS + 1),
        lambda: NeuronControlEnv(n_neurons=40_000),
        lambda: EnvConfig(n_neurons=40_000),
    ):
        with pytest.raises(ValueError, match=f"n_neurons must be .*{MAX_N_NEURONS}"):
            call()
    with pytest.raises(ValueError, match="buffer_size"):
        from spikectl.training.replay import EpisodeReplay

        EpisodeReplay(10**12, 8, 60)


# --- Every CLI error is one line, exit 2, naming the flag ------------------------------


@pytest.mark.parametrize(
    ("flag", "value"),
    [("--gamma", "2"), ("--learning-rate", "inf"), ("--learning-rate", "-1"), ("--tau", "0"),
     ("--seed", "-1"), ("--context-seed", "-3"), ("--batch-size", "0"), ("--num-envs", "0"),
     ("--n-neurons", "1"), ("--n-neurons", "100000"), ("--episode-length", "1"),
     ("--n-train", "0"), ("--n-test", "0"), ("--buffer-size", "0"), ("--learning-starts", "-1"),
     ("--updates-per-round", "-1"), ("--eval-every-episodes", "0"),
     ("--checkpoint-every-episodes", "0"), ("--epsilon-start", "1.5"), ("--epsilon-end", "nan"),
     ("--epsilon-anneal-fraction", "-0.1"), ("--max-grad-norm", "-1"),
     ("--max-grad-norm", "inf"), ("--total-env-steps", "10"), ("--torch-threads", "-1"),
     ("--device", "tpu")],
)  # fmt: skip
def test_every_train_config_error_names_its_flag(flag, value, tmp_path, capsys):
    line = cli_error(["train", "smoke", flag, value, "--run-dir",
                      str(tmp_path / "run")], capsys)  # fmt: skip
    assert flag in line
    assert not (tmp_path / "run").exists(), "a refused start left a directory behind"


@pytest.mark.parametrize(
    ("argv", "named"),
    [(["train", "--seed", "abc"], "--seed: invalid literal"),
     (["train", "--total-env-steps", "1e5"], "--total-env-steps"),
     (["train", "--gamma"], "'--gamma'"),
     (["train", "--arch", "nope"], "'--arch'"),
     (["train", "--sizes.head-hidden", "a", "b"], "--sizes.head-hidden"),
     (["train", "--sizes.lstm-hidden", "0"], "--sizes.lstm-hidden must be an int >= 1"),
     (["train", "--sizes.do-nothing-head", "x"], "--sizes.do-nothing-head must be one of"),
     (["sweep", "--workers", "x"], "--workers"),
     (["contexts", "--n-neurons", "q"], "--n-neurons"),
     (["baselines", "--hidden-fraction", "2"], "--hidden-fraction must lie in [0, 1)"),
     (["baselines", "--observation-noise-mV", "-1"], "--observation-noise-mV must be >= 0"),
     (["evaluate"], "PATH"),
     (["nosuch"], "nosuch"),
     ([], "missing subcommand")],
)  # fmt: skip
def test_parse_errors_are_one_line_naming_the_flag(argv, named, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    line = cli_error(argv, capsys)
    assert named in line and "╭" not in line and "│" not in line
    assert list(tmp_path.iterdir()) == [], "a refused command wrote something"


def test_help_and_unreadable_frames_pass_through(capsys):
    from spikectl.cli import parse_error_line

    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--help"])
    assert exit_info.value.code == 0
    assert "--total-env-steps" in capsys.readouterr().out
    assert parse_error_line("a warning\nnot a frame\n") is None
    assert parse_error_line("╭─ Value error ─╮\n╰───╯\n") is None  # nothing in it to say
    boxed = ("╭─ Value error ──╮\n│ Error parsing --seed: bad │\n│ ──── │\n"
             "│ see spikectl train --help │\n╰──╯")  # fmt: skip
    dashed = (" Value error \n ------ \n  Error parsing --seed: bad \n  -----\n"
              "  see spikectl train --help")  # fmt: skip
    assert (
        parse_error_line(boxed)
        == parse_error_line(dashed)
        == ("--seed: bad (see spikectl train --help)")
    )


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_device_cuda_without_cuda(tmp_path, capsys):
    line = cli_error(["train", *TINY_FLAGS, "--device", "cuda", "--run-dir",
                      str(tmp_path / "run")], capsys)  # fmt: skip
    assert "--device" in line and "CUDA" in line
    assert not (tmp_path / "run").exists()


def test_other_command_errors_are_one_line(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert "is a file" in cli_error(["train", *TINY_FLAGS, "--run-dir", str(tmp_path / "file")],
                                    capsys)  # fmt: skip
    assert "--workers" in cli_error(["sweep", "--preset", "fig4", "--workers", "-2",
                                     "--sweep-dir", str(tmp_path / "s")], capsys)  # fmt: skip
    (tmp_path / "sweep.json").mkdir()
    assert "folder" in cli_error(["sweep", "--config", str(tmp_path / "sweep.json")], capsys)
    (tmp_path / "list.json").write_text("[1, 2]")
    assert "JSON object" in cli_error(["sweep", "--config", str(tmp_path / "list.json")], capsys)
    assert "--seed" in cli_error(["contexts", "--seed", "-1", "--out-dir", str(tmp_path)], capsys)
    assert "config.json" in cli_error(["evaluate", str(tmp_path / "nothing")], capsys)
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "config.json").mkdir()
    assert "config.json" in cli_error(["evaluate", str(tmp_path / "bad")], capsys)


def fail_writes(monkeypatch, name: str, code: int) -> None:
    """Make the atomic writer fail (disk full, read-only, ...) for files called ``name``."""
    import spikectl.files as files

    real_replace = os.replace

    def replace(source, target):
        if Path(target).name == name:
            raise OSError(code, os.strerror(code))
        real_replace(source, target)

    monkeypatch.setattr(files.os, "replace", replace)


@pytest.mark.parametrize(
    ("name", "code"),
    [pytest.param("train_contexts.npz", errno.EROFS, marks=pytest.mark.slow),
     ("config.json", errno.ENOSPC), ("checkpoint.pt", errno.ENOSPC),
     pytest.param("model.pt", errno.ENOSPC, marks=pytest.mark.slow)],
)  # fmt: skip
def test_full_or_read_only_disk_is_one_line_and_no_trap(name, code, tmp_path, capsys,
                                                        monkeypatch):  # fmt: skip
    run = tmp_path / "run"
    command = ["train", *TINY_FLAGS, "--run-dir", str(run)]
    with monkeypatch.context() as patch:
        fail_writes(patch, name, code)
        line = cli_error(command, capsys)
    assert name in line and ("no space" in line or "read-only" in line)
    assert not list(run.glob(".*.tmp")), "a temporary file was left behind"
    # The disk is fixed: the same command runs, or (after a checkpoint) resume does.
    try:
        main(command)
    except SystemExit:
        assert f"spikectl train --resume {run}" in capsys.readouterr().err
        main(["train", "--resume", str(run)])
    assert load_model_weights(run / "model.pt")


# --- No recovery traps ----------------------------------------------------------------


def metric_rows(run: Path) -> list[list[str]]:
    rows = [line.split(",") for line in (run / "metrics.csv").read_text().splitlines()]
    clocks = {rows[0].index(clock) for clock in CLOCK_FIELDS}
    return [[v for i, v in enumerate(row) if i not in clocks] for row in rows]  # no clocks


@pytest.mark.parametrize("how", ["same command", pytest.param("resume", marks=pytest.mark.slow)])
def test_a_run_stopped_before_its_first_checkpoint_restarts_exactly(
    how, finished_run, tmp_path, capsys, monkeypatch
):
    import spikectl.training.run as dqn

    def out_of_disk(*args):
        raise FileWriteError(errno.ENOSPC, "cannot write checkpoint.pt: no space left")

    run = tmp_path / how
    command = ["train", *TINY_FLAGS, "--run-dir", str(run)]
    with monkeypatch.context() as patch:
        patch.setattr(dqn, "save_checkpoint", out_of_disk)
        cli_error(command, capsys)
    assert (run / "config.json").exists() and not (run / "checkpoint.pt").exists()
    main(command if how == "same command" else ["train", "--resume", str(run)])
    assert metric_rows(run) == metric_rows(finished_run)
    ours, reference = (load_model_weights(r / "model.pt") for r in (run, finished_run))
    assert all(torch.equal(ours[key], reference[key]) for key in reference)


def test_a_failed_start_does_not_block_the_same_command(run_copy, tmp_path, capsys):
    contexts = tmp_path / "mine.npz"
    contexts.write_text("not yet written")
    command = ["train", *TINY_FLAGS, "--train-contexts", str(contexts), "--run-dir",
               str(tmp_path / "new")]  # fmt: skip
    assert "mine.npz" in cli_error(command, capsys)
    shutil.copy(run_copy / "train_contexts.npz", contexts)
    main(command)
    assert load_model_weights(tmp_path / "new" / "model.pt")


def test_two_processes_never_train_one_run_dir(tmp_path):
    run = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time; from pathlib import Path; from spikectl.training.run_files import "
         "run_lock\nwith run_lock(Path(sys.argv[1])):\n print('locked', flush=True)\n "
         "time.sleep(60)", str(run)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(RunDirError, match=f"another process \\(pid {holder.pid}\\)"):
            train(TINY, run)
    finally:
        holder.kill()
        holder.wait()
    with run_lock(run):  # released when its process died
        pass


def test_contexts_command_refuses_to_overwrite(tmp_path, capsys):
    command = ["contexts", "--out-dir", str(tmp_path), "--n-train", "3", "--n-test", "2"]
    main(command)
    before = (tmp_path / "train_contexts.npz").read_bytes()
    line = cli_error([*command, "--seed", "5"], capsys)
    assert "--overwrite" in line
    assert (tmp_path / "train_contexts.npz").read_bytes() == before
    main([*command, "--seed", "5", "--overwrite"])
    assert (tmp_path / "train_contexts.npz").read_bytes() != before


# --- No orphans -------------------------------------------------------------------------


def children(pid: int) -> set[int]:
    found = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        found |= {int(child) for child in (task / "children").read_text().split()}
    return found


@pytest.mark.slow  # 18 s
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_killing_a_sweep_stops_its_workers(tmp_path, wait_until):
    sweep_file = tmp_path / "sweep.json"
    sweep_file.write_text(json.dumps(
        {"base": "smoke", "overrides": {"total_env_steps": 10**7}, "grid": {"seed": [0, 1]}}
    ))  # fmt: skip
    sweep_dir = tmp_path / "sweep"
    parent = subprocess.Popen(
        [sys.executable, "-m", "spikectl.cli", "sweep", "--config", str(sweep_file),
         "--sweep-dir", str(sweep_dir), "--workers", "2"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
    )  # fmt: skip
    wait_until(
        lambda: all((sweep_dir / "trials" / f"seed={s}" / "metrics.csv").exists() for s in (0, 1)),
        "both trials started", timeout_s=120, process=parent,
    )  # fmt: skip
    workers = children(parent.pid)
    assert workers
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    os.set_blocking(parent.stdout.fileno(), False)
    deadline = time.monotonic() + 30
    while True:  # EOF on the caller's pipe: nobody holds it any more
        try:
            if parent.stdout.read() == b"":
                break
        except BlockingIOError:
            pass
        assert time.monotonic() < deadline, "workers outlived the sweep, holding its pipe"
        time.sleep(0.1)
    wait_until(
        lambda: not any(Path(f"/proc/{pid}").exists() for pid in workers),
        "the end of the sweep's workers", timeout_s=30,
    )  # fmt: skip


# --- API arguments --------------------------------------------------------------------


@pytest.mark.parametrize("seed", [-1, 1.5, "abc", None, True])
def test_generate_names_a_bad_seed(seed):
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        ContextSet.generate(2, n_neurons=4, episode_length=10, seed=seed)


@pytest.mark.parametrize(("name", "value"), [("n_neurons", 3.0), ("episode_length", 10.0),
                                             ("size", 2.0), ("n_neurons", "8")])  # fmt: skip
def test_generate_names_a_non_integer_size(name, value):
    arguments = {"size": 2, "n_neurons": 4, "episode_length": 10, name: value}
    with pytest.raises(ValueError, match=f"{name} must be"):
        ContextSet.generate(**arguments)


def test_numpy_scalars_are_accepted_like_python_ones():
    numpy_set = ContextSet.generate(np.int64(3), n_neurons=np.int32(4),
                                    episode_length=np.int64(10), seed=np.uint8(1))  # fmt: skip
    assert numpy_set == ContextSet.generate(3, n_neurons=4, episode_length=10, seed=1)
    assert numpy_set.seed == 1 and type(numpy_set.seed) is int
    env = NeuronControlEnv(contexts=numpy_set)
    obs, info = env.reset(seed=0, options={"context": np.int64(2)})
    assert info["context_index"] == 2


@pytest.mark.parametrize("options", [[("context", 1)], "context", 3])
def test_reset_options_must_be_a_dict(options):
    contexts = ContextSet.generate(2, n_neurons=4, episode_length=10)
    with pytest.raises(TypeError, match="options must be a dict"):
        NeuronControlEnv(contexts=contexts).reset(options=options)
    with pytest.raises(TypeError, match="options must be a dict"):
        NeuronControlVectorEnv(2, contexts=contexts).reset(options=options)
    with pytest.raises(TypeError, match="options must be a dict"):
        gym.make("spikectl/NeuronControl-v0", contexts=contexts).reset(options=options)


@pytest.mark.parametrize("bug", [TypeError, RuntimeError, AttributeError, KeyError])
def test_cli_keeps_the_traceback_of_a_bug(monkeypatch, bug):
    """Only user errors become one-line messages; a bug inside a command propagates."""
    import spikectl.cli as cli

    def broken(config):
        raise bug("a bug in the command")

    monkeypatch.setitem(cli.COMMANDS, "demo", (broken, cli.DemoConfig))
    with pytest.raises(bug, match="a bug in the command"):
        main(["demo"])


def test_cli_reports_a_user_error_of_a_command_in_one_line(monkeypatch, capsys):
    import spikectl.cli as cli

    def refuses(config):
        raise ValueError("n_test must be a positive integer, got 0")

    monkeypatch.setitem(cli.COMMANDS, "demo", (refuses, cli.DemoConfig))
    assert cli_error(["demo"], capsys) == (
        "spikectl: error: --n-test must be a positive integer, got 0"
    )
