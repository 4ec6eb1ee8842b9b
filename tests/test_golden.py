"""Nothing changes for users: the golden runs (tests/golden/golden_runs.py), recorded before
the one-loop refactor, train to the same metrics and bit-identical networks today, alone,
as seeds of a group, and after a SIGKILL and a resume.

The record is bit-exact on the CPU kind and PyTorch it was made with; elsewhere these
tests skip and say so (numerics differ between CPU kinds: docs/reliability.md)."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent / "golden"))
from golden_runs import (  # noqa: E402
    GOLDEN_FILE,
    QUICK_PREFIX,
    RUNS,
    STACKED_GROUP,
    machine,
    record,
)

GOLDEN = json.loads(GOLDEN_FILE.read_text())

pytestmark = pytest.mark.skipif(
    machine() != GOLDEN["machine"],
    reason=f"the golden runs were recorded on {GOLDEN['machine']}; this is {machine()}: "
    "bit-exact comparison is meaningful only there",
)


def _train(args: tuple[str, ...], run_dir: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "spikectl.cli", *args, "--run-dir", str(run_dir)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip


@pytest.mark.parametrize(
    "name",
    [pytest.param("quick-prefix", marks=pytest.mark.slow), "smoke-seed0"],  # 48 s and 18 s
)
def test_a_single_run_matches_its_golden_record(tmp_path, name):
    _train(RUNS[name], tmp_path / name)
    assert record(tmp_path / name) == GOLDEN["runs"][name]


def test_each_seed_of_a_group_matches_that_seed_trained_alone(tmp_path):
    """`train smoke --seeds 0 1`: seed k's metrics and networks are those of seed k alone."""
    _train(("train", "smoke", "--seeds", "0", "1"), tmp_path / "group")
    for seed in (0, 1):
        assert record(tmp_path / "group" / f"seed={seed}") == GOLDEN["runs"][f"smoke-seed{seed}"]


@pytest.mark.slow  # 19 s
def test_a_stacked_group_trains_as_groups_did_before_the_refactor(tmp_path):
    """`--stacked`: the seed group of one stacked computation, exactly as it trained."""
    _train((*STACKED_GROUP, "--stacked"), tmp_path / "group")
    for seed in (0, 1):
        assert (
            record(tmp_path / "group" / f"seed={seed}")
            == GOLDEN["runs"][f"smoke-stacked-group-seed{seed}"]
        )


@pytest.mark.slow  # 55 s; kill-and-resume exactness stays in test_training (paper)
def test_a_resume_after_sigkill_matches_the_golden_record(tmp_path, wait_until, run_cli):
    """Killed after its first checkpoint (episode 32 of 96), resumed: the golden record."""
    run_dir = tmp_path / "killed"
    process = subprocess.Popen(
        [sys.executable, "-m", "spikectl.cli", *QUICK_PREFIX, "--run-dir", str(run_dir)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    wait_until(lambda: (run_dir / "checkpoint.pt").exists(), "a checkpoint", 300, process)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert not (run_dir / "model.pt").exists(), "killed too late to test anything"
    run_cli("train", "--resume", str(run_dir))
    assert record(run_dir) == GOLDEN["runs"]["quick-prefix"]


@pytest.mark.slow  # 14 s
def test_a_run_of_the_double_q_trainer_before_the_refactor_resumes_exactly(tmp_path, run_cli):
    """tests/data/format2-smoke-run: `train smoke` of the pre-refactor trainer, killed
    after its first checkpoint (checkpoint format 2, the learner's settings in the
    config's train section). Resumed today, it ends as the uninterrupted run did."""
    import shutil

    from spikectl.training.run_files import read_metrics

    run_dir = tmp_path / "run"
    shutil.copytree(Path(__file__).parent / "data" / "format2-smoke-run", run_dir)
    run_cli("train", "--resume", str(run_dir))
    assert record(run_dir) == GOLDEN["runs"]["smoke-seed0"]
    # It had no evaluation clock, and says so rather than counting from zero.
    assert all(math.isnan(row["eval_cpu_time_s"]) for row in read_metrics(run_dir))
