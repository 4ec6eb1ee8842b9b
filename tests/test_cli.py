"""The command line: demo and contexts subcommands, and their errors."""

from __future__ import annotations

import json

import pytest

from spikectl import ContextSet
from spikectl.cli import main


def test_demo_scores_reference_policies(tmp_path, capsys):
    main(["demo", "--out-dir", str(tmp_path), "--n-train", "12", "--n-test", "8"])
    results = json.loads((tmp_path / "results.json").read_text())["returns"]
    assert abs(results["do-nothing"]["train"] - 0.5) < 1e-12
    assert abs(results["do-nothing"]["test"] - 0.5) < 1e-12
    assert abs(results["witness"]["test"] - 1.0) < 1e-12
    assert 0.3 < results["random"]["train"] < 0.7
    assert (tmp_path / "raster.png").stat().st_size > 10_000
    assert len(ContextSet.load(tmp_path / "test_contexts.npz")) == 8
    assert "witness" in capsys.readouterr().out


def test_contexts_generate_and_show(tmp_path, capsys):
    main(["contexts", "--out-dir", str(tmp_path), "--n-train", "5", "--n-test", "3", "--seed", "2"])
    train = ContextSet.load(tmp_path / "train_contexts.npz")
    test = ContextSet.load(tmp_path / "test_contexts.npz")
    assert (len(train), len(test)) == (5, 3) and train.duplicate_topologies(test) == []
    main(["contexts", "--action", "show", "--path", str(tmp_path / "test_contexts.npz")])
    assert "checksum" in capsys.readouterr().out


def test_errors_are_one_line_messages(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["contexts", "--action", "show", "--path", str(tmp_path / "missing.npz")])
    assert exit_info.value.code == 2
    assert "not found" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--n-train", "0"])
    assert "--n-train must be a positive integer" in capsys.readouterr().err


def test_resume_refuses_the_flags_it_would_ignore(tmp_path, run_cli):
    """`train --resume RUN` continues the saved config; other settings are refused in one
    line naming them, and the run is left as it was."""
    run_cli("train", "smoke", "--total-env-steps", "320", "--run-dir", str(tmp_path / "run"))
    before = (tmp_path / "run" / "metrics.csv").read_text()
    refused = run_cli("train", "--resume", str(tmp_path / "run"), "--total-env-steps", "9600",
                      "--learning-rate", "0.1", "--run-dir", "x", check=False)  # fmt: skip
    assert refused.returncode == 2
    (line,) = refused.stderr.strip().splitlines()
    assert "--resume continues the run exactly as it was saved" in line
    assert "--run-dir, --total-env-steps, --learning-rate" in line
    assert (tmp_path / "run" / "metrics.csv").read_text() == before
    assert run_cli("train", "smoke", "--resume", str(tmp_path / "run")).returncode == 0
