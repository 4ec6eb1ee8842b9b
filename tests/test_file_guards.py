"""Reliability round 4 (issue 40), files a user points at: every one goes through one
guarded open, and the sizes a file declares are checked against limits and the file's
real size before anything is allocated.

Class 1: a FIFO, a link to /dev/zero or a folder as checkpoint.pt, through every
command that reads it (evaluate, train --resume, benchmark, realtime). Class 2: a policy
header declaring 10^9 neurons, an .npz member claiming gigabytes from a few bytes (a
context set and a policy file), simulate with 10^9 steps, num_envs 10^9. Class 4: a
renamed metrics.csv column, a policy header nested 100 000 deep. Class 14: a damaged
machine.json is reported and kept.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import no_hang

from spikectl.agents import make_agent
from spikectl.agents.compiled import CompiledPolicy, PolicyFileError
from spikectl.agents.policy_file import _policy_bytes
from spikectl.cli import main
from spikectl.contexts import ContextSet, make_splits
from spikectl.contexts.file_format import ContextFileError
from spikectl.files import TooLargeError, npz_size_problem
from spikectl.training.run_files import RunDirError, read_metrics

SMOKE_RUN = Path(__file__).parent / "data" / "format2-smoke-run"


def cli(args: list[str], capsys) -> tuple[int, str]:
    """Run the command line in this process: (exit status, stderr)."""
    with no_hang():
        try:
            main([str(arg) for arg in args])
            code = 0
        except SystemExit as exit:
            code = exit.code
    return code, capsys.readouterr().err


def one_line(err: str) -> str:
    (line,) = err.strip().splitlines()
    assert line.startswith("spikectl: error:") and "Traceback" not in err
    return line


BAD_FILES = {
    "fifo": lambda path: os.mkfifo(path),
    "dev-zero": lambda path: path.symlink_to("/dev/zero"),
    "folder": lambda path: path.mkdir(),
}


@pytest.fixture
def run_copy(tmp_path) -> Path:
    run = tmp_path / "run"
    shutil.copytree(SMOKE_RUN, run)
    return run


@pytest.mark.parametrize("kind", list(BAD_FILES))
@pytest.mark.parametrize("command", ["evaluate", "resume", "realtime", "compiled"])
def test_a_checkpoint_that_is_not_a_regular_file_is_one_line(run_copy, kind, command, capsys):
    """Class 1: checkpoint.pt was the one run file still read unguarded (a FIFO hung
    evaluate). Every command that reads it refuses it at once, naming it (benchmark
    loads a run through the same load_agent; the smoke run cannot play the suite)."""
    (run_copy / "checkpoint.pt").unlink()
    BAD_FILES[kind](run_copy / "checkpoint.pt")
    argv = {
        "evaluate": ["evaluate", run_copy],
        "resume": ["train", "--resume", run_copy],
        "realtime": ["realtime", run_copy, "--episodes", "1"],
        "compiled": ["realtime", run_copy, "--episodes", "1", "--compiled"],
    }[command]
    code, err = cli(argv, capsys)
    assert code == 2
    line = one_line(err)
    assert "checkpoint.pt" in line
    assert any(word in line for word in ("FIFO", "character device", "folder"))


def zip_bomb_npz(path: Path, name: str, shape: tuple[int, ...], extra: dict | None = None):
    """An .npz whose member ``name`` is a float64 array of zeros of ``shape``: compressed,
    it takes about a thousandth of what it claims."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": shape}
    )
    zeros = bytes(2**20)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for key, array in (extra or {}).items():
            buffer = io.BytesIO()
            np.save(buffer, array)
            archive.writestr(f"{key}.npy", buffer.getvalue())
        with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
            member.write(header.getvalue())
            for _ in range(int(np.prod(shape)) * 8 // len(zeros)):
                member.write(zeros)


def test_a_small_context_file_claiming_gigabytes_is_refused_before_allocation(tmp_path):
    """Class 2: a 1 MB file whose weights claim 1 GiB (consistent zip sizes) was read in
    full; the claim is compared with the bytes the member takes in the file."""
    path = tmp_path / "bomb.npz"
    zip_bomb_npz(path, "weights", (2**27,), {"metadata": np.array("{}")})
    assert path.stat().st_size < 2 * 2**20
    with no_hang(), pytest.raises(ContextFileError, match=r"bomb.npz is refused: array 'weights'"):
        ContextSet.load(path)
    assert "more than 400 times" in npz_size_problem(path)


def test_a_policy_file_claiming_gigabytes_is_refused_before_allocation(tmp_path):
    path = tmp_path / "bomb.npz"
    zip_bomb_npz(path, "lstm.lstm.weight_ih_l0", (2**27,))
    with no_hang(), pytest.raises(PolicyFileError, match="is refused: array"):
        CompiledPolicy.load(path)


def policy_with_header(tmp_path: Path, change) -> Path:
    """A policy file whose header is changed by ``change(header)`` (checksum kept)."""
    data = np.load(io.BytesIO(_policy_bytes(make_agent("tdrqn", 5, 20))))
    arrays = {name: data[name] for name in data.files}
    header = json.loads(str(arrays["metadata"]))
    change(header)
    arrays["metadata"] = np.array(json.dumps(header) if isinstance(header, dict) else header)
    path = tmp_path / "policy.npz"
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda h: h.update(n_neurons=10**9), "n_neurons is 1000000000, above 1024"),
        (lambda h: h.update(episode_length=10**9), "episode_length is 1000000000, above"),
        (lambda h: h.update(lstm_hidden=10**6), "lstm_hidden is 1000000, above 4096"),
        (lambda h: h.update(head_hidden=[32, 10**7]), "head_hidden is"),
        (lambda h: h.update(v_threshold_mV=1e308), "beyond"),
        (lambda h: h.update(v_threshold_mV=-80.0), "must be above v_rest_mV"),
        (lambda h: h.update(n_neurons=1), "must be >= 2"),
        (lambda h: h.update(layer_norm_eps=5.0), "layer_norm_eps 5.0 must be < 1"),
        (lambda h: h.update(do_nothing_head="pooled"), "checksum does not match"),
        (lambda h: h.update(checksum="0" * 64), "checksum does not match"),
        (lambda h: h.update(format_version=1), "format version 1; this spikectl reads version 2"),
    ],
)
def test_policy_headers_out_of_range_or_altered_are_refused(tmp_path, change, message):
    """Class 10 and class 2: header values out of range (checked before anything of
    their size is allocated) and a header changed over the same weights (the checksum
    covers both) are one PolicyFileError naming the file."""
    path = policy_with_header(tmp_path, change)
    with no_hang(), pytest.raises(PolicyFileError, match=message):
        CompiledPolicy.load(path, warm_up=False)


def test_a_policy_header_nested_deeply_is_one_line(tmp_path, capsys):
    """Class 4: a header nested 100 000 deep was a RecursionError traceback."""
    path = tmp_path / "policy.npz"
    np.savez(path, metadata=np.array("[" * 100_000 + "]" * 100_000))
    with pytest.raises(PolicyFileError, match="nested too deeply"):
        CompiledPolicy.load(path)
    code, err = cli(["realtime", path, "--episodes", "1"], capsys)
    assert code == 2 and "nested too deeply" in one_line(err)


def test_a_policy_header_of_a_billion_neurons_is_one_line_on_the_command_line(tmp_path, capsys):
    """Class 2: ``spikectl realtime pol.npz`` took 17 s, then a MemoryError traceback."""
    path = policy_with_header(tmp_path, lambda h: h.update(n_neurons=10**9))
    code, err = cli(["realtime", path, "--episodes", "1"], capsys)
    assert code == 2 and "n_neurons is 1000000000" in one_line(err)


def test_simulate_and_the_vector_environment_refuse_runaway_sizes(monkeypatch):
    """Class 2: simulate with 10^9 steps and num_envs=10^9 are named errors, before
    anything of that size is allocated."""
    from spikectl import simulate
    from spikectl.envs.vector_env import NeuronControlVectorEnv

    with no_hang(), pytest.raises(TooLargeError, match="1,000,000,000 steps"):
        simulate(np.zeros((4, 4)), np.broadcast_to(np.int64(-1), (10**9,)))
    # Where memory would hold it, the step limit still refuses it.
    monkeypatch.setattr("spikectl.files.physical_memory_bytes", lambda: 2**50)
    with no_hang(), pytest.raises(TooLargeError, match="steps per call is above the limit"):
        simulate(np.zeros((4, 4)), np.broadcast_to(np.int64(-1), (10**9,)))
    monkeypatch.undo()
    with no_hang(), pytest.raises(TooLargeError, match="num_envs=1,000,000,000"):
        NeuronControlVectorEnv(num_envs=10**9)


def test_a_renamed_metrics_column_is_one_line(run_copy):
    """Class 4: ``plot`` met a renamed metrics.csv column as a KeyError."""
    from spikectl.experiments.report import load_runs

    path = run_copy / "metrics.csv"
    path.write_text(path.read_text().replace("test_return", "test_retrun", 1))
    with pytest.raises(RunDirError, match="metrics.csv is damaged: it has no column test_return"):
        read_metrics(run_copy)
    with pytest.raises(RunDirError, match="no column test_return"):
        load_runs([run_copy])


@pytest.mark.parametrize("content", ["{bad", '{"starts": 5}', "[1, 2]"])
def test_a_damaged_machine_record_is_reported_and_kept(tmp_path, content):
    """Class 14: a damaged machine.json was silently replaced, so the "ran on another
    kind of machine" warning could no longer fire. Now a warning names it and it is
    kept beside as machine.json.damaged."""
    from spikectl.training.machine import record_machine

    (tmp_path / "machine.json").write_text(content)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        record_machine(tmp_path, 8)
    (warning,) = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert "machine.json is damaged" in str(warning.message)
    assert (tmp_path / "machine.json.damaged").read_text() == content
    assert len(json.loads((tmp_path / "machine.json").read_text())["starts"]) == 1


def test_a_wrong_witness_under_a_recomputed_checksum_is_refused(tmp_path):
    """Class 12: witnesses are replayed on load; a set whose witness does not produce
    its pattern (checksum recomputed, so it matches) is refused, naming the context."""
    from spikectl.contexts.context import Context

    _, test = make_splits(3, 4, 5, 20, seed=2)
    witnesses = [c.witness.copy() for c in test]
    witnesses[2][:] = -1  # doing nothing never produces a pattern with spikes
    assert test[2].pattern.any()
    altered = ContextSet(
        [Context(c.weights, c.target, c.pattern, w) for c, w in zip(test, witnesses, strict=True)],
        test.params, test.seed,
    )  # fmt: skip
    altered.save(tmp_path / "altered.npz")
    with pytest.raises(ContextFileError, match="witness of context 2 does not reproduce"):
        ContextSet.load(tmp_path / "altered.npz")
    test.save(tmp_path / "intact.npz")
    assert ContextSet.load(tmp_path / "intact.npz") == test


# --- Round 5 (issue 58): run paths checked before anything is made ---------------------


def test_a_run_directory_name_that_is_not_utf8_is_one_line_and_makes_nothing(tmp_path, capsys):
    """Its files (TensorBoard's among them) record the name as UTF-8: refused at once,
    not a codec message after a half-made run."""
    name = tmp_path / "r\udcff"  # the byte 0xff, as Python reads it from a command line
    code, err = cli(["train", "smoke", "--run-dir", name], capsys)
    assert code == 2 and "is not valid UTF-8" in one_line(err) and "r\\xff" in err
    assert list(tmp_path.iterdir()) == []
    from spikectl.training.presets import SMOKE
    from spikectl.training.run import train

    with pytest.raises(ValueError, match="is not valid UTF-8"):
        train(SMOKE, name)
    assert list(tmp_path.iterdir()) == []


def test_a_run_path_through_a_file_is_named(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("kept")
    code, err = cli(["train", "smoke", "--run-dir", tmp_path / "notes.txt" / "run"], capsys)
    assert code == 2 and f"lies in {tmp_path / 'notes.txt'}, a file" in one_line(err)


@pytest.mark.parametrize("seeds", [None, (0, 1)])
def test_a_refusal_while_a_run_sets_up_leaves_no_directory(tmp_path, seeds):
    """A test set refused after the run directory was made (its episodes are longer than
    the run's), a seed group's too: what was made goes again, nothing half-made stays."""
    from spikectl.training.presets import SMOKE
    from spikectl.training.run import train, train_seeds

    make_splits(3, 3, 5, 30, seed=4)[1].save(tmp_path / "long.npz")
    config = SMOKE.with_changes(test_contexts=tmp_path / "long.npz")
    with pytest.raises(ValueError, match="episodes of 30 steps; the config says 5 and 20"):
        if seeds is None:
            train(config, tmp_path / "run")
        else:
            train_seeds(config, list(seeds), tmp_path / "run")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["long.npz"]
