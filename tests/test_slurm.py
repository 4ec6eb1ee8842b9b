"""``spikectl sweep --backend slurm``: submitit's local executor stands in for a cluster
(each job a process on this machine, requeued on the signal Slurm would send), and a
fake sbatch shows what a cluster would be given."""

from __future__ import annotations

import os
import signal
import stat
import sys
import threading
import time
import types
from pathlib import Path

import pytest

from spikectl.config_errors import MissingExtraError
from spikectl.experiments.backends import Backend
from spikectl.experiments.slurm import SlurmSettings, TrialJob
from spikectl.experiments.sweep import Sweep, SweepError, run_sweep, run_trial
from spikectl.locks import LOCK_FILE
from spikectl.training.presets import SMOKE

TINY = SMOKE.with_changes(total_env_steps=8 * 20 * 4, eval_every_episodes=16,
                           checkpoint_every_episodes=16)  # fmt: skip
LOCAL = SlurmSettings(cluster="local")
quiet = lambda line: None  # noqa: E731


def test_without_submitit_the_slurm_backend_is_one_line_naming_the_extra(
    tmp_path, monkeypatch, capsys
):
    from spikectl.cli import main

    monkeypatch.setitem(sys.modules, "submitit", None)  # import submitit: ImportError
    with pytest.raises(MissingExtraError, match=r"pip install 'spikectl\[slurm\]'"):
        run_sweep(Sweep(TINY, {"seed": [0]}), tmp_path / "s", Backend("slurm", slurm=LOCAL))
    assert not (tmp_path / "s").exists(), "refused before anything was written"
    with pytest.raises(SystemExit):
        main(["sweep", "--preset", "fig4", "--backend", "slurm", "--sweep-dir",
              str(tmp_path / "t")])  # fmt: skip
    err = capsys.readouterr().err
    assert err.splitlines() == [
        "spikectl: error: --backend slurm needs submitit, which is not installed: "
        "pip install 'spikectl[slurm]'"
    ]


def test_slurm_flags_are_checked_and_named(tmp_path, monkeypatch, capsys):
    from spikectl.cli import main

    args = ["sweep", "--preset", "fig4", "--sweep-dir", str(tmp_path / "s")]
    for flags, message in [
        (["--backend", "slurm", "--slurm.time-min", "0"],
         "--slurm.time-min must be a positive number of minutes, got 0"),
        (["--backend", "slurm", "--slurm.additional", "{account: lab}"],
         "--slurm.additional is not valid JSON"),
        (["--backend", "slurm", "--slurm.additional", '["--account=lab"]'],
         "--slurm.additional must be a JSON object of sbatch options"),
        (["--slurm.partition", "gpu"], "--slurm.* options apply to --backend slurm only"),
    ]:  # fmt: skip
        with pytest.raises(SystemExit):
            main([*args, *flags])
        assert capsys.readouterr().err.startswith(f"spikectl: error: {message}"), flags
    # With submitit but no Slurm here: where to run it instead, before anything is written.
    monkeypatch.setitem(sys.modules, "submitit", types.ModuleType("submitit"))
    monkeypatch.setattr("spikectl.experiments.slurm.shutil.which", lambda name: None)
    with pytest.raises(SystemExit):
        main([*args, "--backend", "slurm"])
    assert "no sbatch on this machine" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_the_jobs_go_to_sbatch_as_one_array_with_the_settings(tmp_path, monkeypatch):
    """A fake srun and sbatch: the script a cluster would get (one array, its options,
    the requeue signal), submitted once, the logs in SWEEP_DIR/slurm."""
    pytest.importorskip("submitit")
    from spikectl.experiments.slurm import SLURM_DIR

    bin_dir, copy = tmp_path / "bin", tmp_path / "script.sh"
    bin_dir.mkdir()
    for name, body in (("srun", "exit 0"),
                       ("sbatch", f'cp "$1" {copy}; echo "Submitted batch job 4242"')):  # fmt: skip
        path = bin_dir / name
        path.write_text(f"#!/bin/sh\n{body}\n")
        path.chmod(path.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    settings = SlurmSettings(partition="cpu", time_min=90, mem_gb=4, max_timeouts=5,
                             additional='{"account": "lab", "qos": "low"}')  # fmt: skip
    folder = tmp_path / "sweep" / SLURM_DIR
    executor = settings.executor(folder, "spikectl-sweep", parallelism=2)
    jobs = executor.submit_array([TrialJob(run_trial, (TINY, tmp_path / f"{k}")) for k in range(3)])
    assert [job.job_id for job in jobs] == ["4242_0", "4242_1", "4242_2"]
    script = copy.read_text()
    for line in ("--array=0-2%2", "--partition=cpu", "--time=90", "--mem=4GB", "--account=lab",
                 "--qos=low", "--cpus-per-task=1", "--job-name=spikectl-sweep",
                 "--signal=USR2@", f"--output={folder}/%A_%a_0_log.out"):  # fmt: skip
        assert f"#SBATCH {line}" in script, line
    assert "gpus" not in script and sys.executable in script


def test_the_slurm_backend_gives_the_local_backends_results(tmp_path, assert_same_trials):
    """Seed groups as a job array of submitit's local executor, against the local pool
    training each trial alone: the same metrics and bit-identical weights."""
    pytest.importorskip("submitit")
    sweep = Sweep(TINY, {"arch": ["drqn", "tdrqn"], "seed": [0, 1]})
    run_sweep(sweep, tmp_path / "local", Backend(workers=2), echo=quiet)
    lines = []
    results = run_sweep(sweep, tmp_path / "slurm", Backend("slurm", slurm=LOCAL),
                        group_seeds=True, echo=lines.append)  # fmt: skip
    assert [r["status"] for r in results] == ["trained in a group of 2"] * 4
    assert lines[1].startswith("submitted 2 job(s)")
    assert_same_trials(tmp_path / "local", tmp_path / "slurm")
    assert sorted(p.name for p in (tmp_path / "slurm/slurm").glob("*_result.pkl"))


def _interrupt_when_checkpointed(run_dir: Path, signum: int, sent: list) -> threading.Thread:
    """A thread that sends ``signum`` to the process training ``run_dir`` (the pid in its
    lock file) once the run has a checkpoint and its evaluation at episode 40, before it
    has its final weights: as Slurm signals a job it preempts, or a node kills it."""

    def interrupt() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            metrics, lock = run_dir / "metrics.csv", run_dir / LOCK_FILE
            if ((run_dir / "checkpoint.pt").exists() and metrics.exists()
                    and len(metrics.read_text().splitlines()) >= 3):  # fmt: skip
                pid = lock.read_text().strip()
                if pid.isdigit() and not (run_dir / "model.pt").exists():
                    os.kill(int(pid), signum)
                    sent.append(pid)
                    return
            time.sleep(0.02)

    thread = threading.Thread(target=interrupt, daemon=True)
    thread.start()
    return thread


def test_a_preempted_job_resumes_exactly_and_a_killed_one_with_the_same_command(
    tmp_path, assert_same_trials
):
    """Two trials as jobs of submitit's local executor. One is sent submitit's preemption
    signal (USR2) mid-run: the job is requeued, calls the same trial again, and it resumes
    from its checkpoint. The other is killed (SIGKILL: no signal to catch, as on a node
    failure): the sweep reports it in one line, and the same command resumes it. Both end
    with the metrics and the bit-identical weights of the local backend's run."""
    pytest.importorskip("submitit")
    config = SMOKE.with_changes(total_env_steps=160 * 20, eval_every_episodes=40,
                                checkpoint_every_episodes=40)  # 160 episodes
    sweep = Sweep(config, {"seed": [0, 1]})
    run_sweep(sweep, tmp_path / "local", Backend(workers=2), echo=quiet)
    trials = tmp_path / "slurm" / "trials"
    sent: list[str] = []
    threads = [_interrupt_when_checkpointed(trials / "seed=0", signal.SIGUSR2, sent),
               _interrupt_when_checkpointed(trials / "seed=1", signal.SIGKILL, sent)]  # fmt: skip
    lines: list[str] = []
    with pytest.raises(SweepError, match=r"1 of 2 trial\(s\) failed \(first: seed=1: job "):
        run_sweep(sweep, tmp_path / "slurm", Backend("slurm", slurm=LOCAL), echo=lines.append)
    for thread in threads:
        thread.join()
    assert len(sent) == 2, "a trial ended before it could be interrupted"
    assert any(line.startswith("seed=0: resumed: train") for line in lines), lines
    assert any("seed=1: failed: job" in line and "the same command resumes it" in line
               for line in lines), lines  # fmt: skip
    logs = "".join(path.read_text() for path in (tmp_path / "slurm/slurm").glob("*_log.*"))
    assert "this job is preempted" in logs and "Requeued job" in logs
    again = run_sweep(sweep, tmp_path / "slurm", Backend("slurm", slurm=LOCAL), echo=quiet)
    assert [r["status"] for r in again] == ["skipped (done)", "resumed"]
    assert_same_trials(tmp_path / "local", tmp_path / "slurm")
