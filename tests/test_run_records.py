"""Reliability round 3 (issue 26), the rest: what a run records matches what it was
given and what it holds (best_model.pt across a resume, a context file's size, the
machine), a group checkpoint's entries are checked, a full disk under TensorBoard stops
a run that then resumes exactly, and a misspelt flag gets one clean hint."""

from __future__ import annotations

import copy
import errno
import json
import shutil

import pytest
import torch

from spikectl.cli import main
from spikectl.contexts import make_splits
from spikectl.training.checkpoint import read_checkpoint
from spikectl.training.machine import cpu_description
from spikectl.training.presets import SMOKE
from spikectl.training.run import best_on_validation, train, train_seeds
from spikectl.training.run_files import read_config, read_metrics
from spikectl.training.torch_files import model_episode, payload_checksum, torch_bytes

# Evaluations every 8 episodes, checkpoints every 16, 12 rounds of 8: the best
# validation return of seed 0 comes at episode 16, before the checkpoint at 32 that a
# run interrupted after 5 rounds resumes from.
CONFIG = SMOKE.with_changes(total_env_steps=1920, eval_every_episodes=8,
                            checkpoint_every_episodes=16)  # fmt: skip
FLAGS = ["--total-env-steps", "1920", "--eval-every-episodes", "8",
         "--checkpoint-every-episodes", "16"]  # fmt: skip


def cli(args: list[str], capsys) -> tuple[int, str, str]:
    """Run the command line in this process: (exit status, stdout, stderr)."""
    try:
        main(args)
        code = 0
    except SystemExit as exit:
        code = exit.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("whole") / "run"
    train(CONFIG, run_dir)
    return run_dir


def test_a_damaged_best_model_is_set_aside_and_restored_on_resume(
    tmp_path, uninterrupted, interrupt_after_rounds, capsys, comparable
):
    """Issue 26, class 9: resume deleted a damaged (or crafted) best_model.pt while the
    final table and metrics.csv still named it. Now the checkpoint keeps the best
    network: the file is moved aside (a warning names both) and written again."""
    run_dir = tmp_path / "run"
    stop = interrupt_after_rounds(5)
    with pytest.raises(KeyboardInterrupt):
        train(CONFIG, run_dir)
    stop()
    (run_dir / "best_model.pt").write_bytes(b"not a model")
    code, out, err = cli(["train", "--resume", str(run_dir)], capsys)
    assert code == 0
    (warning,) = err.strip().splitlines()
    assert "best_model.pt" in warning and "best_model.set-aside.pt" in warning
    assert (run_dir / "best_model.set-aside.pt").read_bytes() == b"not a model"
    best = best_on_validation(read_metrics(run_dir))
    assert model_episode(run_dir / "best_model.pt") == best["episode"]
    assert f"episode {int(best['episode']):,}: best_model.pt" in out
    assert comparable(read_metrics(run_dir)) == comparable(read_metrics(uninterrupted))
    ours = torch.load(run_dir / "best_model.pt", weights_only=True)
    theirs = torch.load(uninterrupted / "best_model.pt", weights_only=True)
    assert all(torch.equal(ours[name], theirs[name]) for name in theirs)


def test_a_context_files_size_is_what_the_run_records(tmp_path, capsys):
    """Issue 26, class 9: --train-contexts with 10 contexts recorded the preset's
    n_train. The run records the file's size; an --n-train that contradicts the file is
    refused naming both; resume and evaluate work on such a run."""
    train_set, test_set = make_splits(10, 7, 5, 20, seed=3)
    train_set.save(tmp_path / "train.npz")
    test_set.save(tmp_path / "test.npz")
    run_dir = tmp_path / "run"
    given = ["--train-contexts", str(tmp_path / "train.npz"), "--total-env-steps", "640"]
    code, _, err = cli(["train", "smoke", *given, "--n-train", "5", "--run-dir", str(run_dir)],
                       capsys)  # fmt: skip
    assert code == 2 and not run_dir.exists()
    assert "--n-train 5" in err and "holds 10 contexts" in err
    assert cli(["train", "smoke", *given, "--run-dir", str(run_dir)], capsys)[0] == 0
    assert (read_config(run_dir).env.n_train, read_config(run_dir).env.n_test) == (10, 6)
    assert cli(["train", "--resume", str(run_dir)], capsys)[0] == 0
    code, out, _ = cli(["evaluate", str(run_dir)], capsys)
    assert code == 0 and "over 10 contexts" in out
    api = train(SMOKE.with_changes(test_contexts=tmp_path / "test.npz", total_env_steps=640),
                tmp_path / "api")  # fmt: skip
    assert api and read_config(tmp_path / "api").env.n_test == 7


@pytest.fixture(scope="module")
def group_dir(tmp_path_factory):
    """A seed group of two interrupted after its checkpoint at episode 16."""
    from spikectl.training import run as run_module

    group = tmp_path_factory.mktemp("group") / "group"
    real, calls = run_module.Loop.round, {"n": 0}

    def round_then_stop(self):
        real(self)
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt

    run_module.Loop.round = round_then_stop
    try:
        with pytest.raises(KeyboardInterrupt):
            train_seeds(CONFIG, [0, 1], group)
    finally:
        run_module.Loop.round = real
    return group


def _seed0(payload):
    return payload["learners"]["seeds"][0]


CRAFTED = {
    "a metrics row of text": lambda p: p["runs"][0]["metrics"][0].update(val_return="high"),
    "metrics that are not rows": lambda p: p["runs"][0].update(metrics=[1, 2]),
    "no metrics": lambda p: p["runs"][0].update(metrics=[]),
    "no baselines": lambda p: p["runs"][0].update(baselines={}),
    "seeds out of lockstep": lambda p: p["runs"][1].update(episodes=8),
    "an episode past the end": lambda p: [run.update(episodes=10**9) for run in p["runs"]],
    "a clock of NaN": lambda p: p["runs"][0].update(wall_time_s=float("nan")),
    "a negative evaluation clock": lambda p: p["runs"][0].update(eval_cpu_time_s=-1.0),
    "an extra entry": lambda p: p.update(surprise=torch.zeros(3)),
    "an extra learner entry": lambda p: _seed0(p).update(extra=1),
    "no replay buffer": lambda p: _seed0(p).pop("replay"),
    "a misshapen replay buffer": lambda p: _seed0(p)["replay"].update(voltage=torch.zeros(2)),
    "actions out of range": lambda p: _seed0(p)["replay"]["actions"].add_(1000),
    "a negative counter": lambda p: _seed0(p).update(updates=-10),
    "misshapen optimiser moments": lambda p: [
        moments.update(exp_avg=torch.zeros(1))
        for moments in _seed0(p)["optimizer"]["state"].values()
    ],
    "a learning rate of text": lambda p: _seed0(p)["optimizer"]["param_groups"][0].update(lr="x"),
    "a best network that does not fit": lambda p: p["runs"][0].update(
        best_model={"episode": 8, "weights": {"x": torch.zeros(2)}}
    ),
}


@pytest.mark.parametrize("name", list(CRAFTED))
def test_a_group_checkpoint_with_wrong_entries_is_one_line(tmp_path, group_dir, name, capsys):
    """Issue 26, class 6: a seed group's checkpoint with missing, extra or misshapen
    entries under a recomputed checksum (crafted, or written by a bug) is refused in one
    line naming the file, before anything is trained or written."""
    work = tmp_path / "group"
    shutil.copytree(group_dir, work)
    payload = read_checkpoint(work / "checkpoint.pt")
    crafted = copy.deepcopy(payload)
    CRAFTED[name](crafted)
    crafted["checksum"] = payload_checksum(crafted)
    (work / "checkpoint.pt").write_bytes(torch_bytes(crafted))
    before = (work / "seed=0" / "metrics.csv").read_bytes()
    code, _, err = cli(["train", "--resume", str(work)], capsys)
    assert code == 2, err
    (line,) = err.strip().splitlines()
    assert line.startswith("spikectl: error:") and "checkpoint.pt" in line
    assert (work / "seed=0" / "metrics.csv").read_bytes() == before


@pytest.mark.parametrize("point", ["__init__", "add_scalar", "flush", "close"])
def test_a_full_disk_under_tensorboard_stops_the_run_and_it_resumes_exactly(
    tmp_path, uninterrupted, point, monkeypatch, capsys, comparable
):
    """Issue 26, class 5: ENOSPC from inside TensorBoard's writer, at each of its calls,
    is one line naming the log and how to resume (exit 2); checkpoint.pt and metrics.csv
    are intact and the resumed run ends as an uninterrupted one."""
    from torch.utils.tensorboard import SummaryWriter

    real = getattr(SummaryWriter, point)
    calls = {"n": 0}
    fail_at = {"__init__": 1, "add_scalar": 9, "flush": 4, "close": 1}[point]

    def full_disk(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] >= fail_at:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(SummaryWriter, point, full_disk)
    run_dir = tmp_path / "run"
    code, _, err = cli(["train", "smoke", *FLAGS, "--run-dir", str(run_dir)], capsys)
    monkeypatch.setattr(SummaryWriter, point, real)
    assert code == 2
    (line,) = err.strip().splitlines()
    assert "no space left" in line and "tensorboard" in line and "--resume" in line
    if (run_dir / "checkpoint.pt").exists():
        saved = read_checkpoint(run_dir / "checkpoint.pt")["runs"][0]["metrics"]
        assert comparable(read_metrics(run_dir)[: len(saved)]) == comparable(saved)
    assert cli(["train", "--resume", str(run_dir)], capsys)[0] == 0
    assert comparable(read_metrics(run_dir)) == comparable(read_metrics(uninterrupted))
    ours = torch.load(run_dir / "model.pt", weights_only=True)
    theirs = torch.load(uninterrupted / "model.pt", weights_only=True)
    assert all(torch.equal(ours[name], theirs[name]) for name in theirs)


def test_the_cpu_is_read_from_cpuinfo_and_degrades_elsewhere():
    cpuinfo = ("processor\t: 0\nmodel name\t: AMD EPYC\nflags\t\t: fpu sse2 avx2 fma\n\n"
               "processor\t: 1\nmodel name\t: other\n")  # fmt: skip
    assert cpu_description(cpuinfo) == {"cpu": "AMD EPYC", "avx2": True, "avx512f": False}
    elsewhere = cpu_description("")
    assert elsewhere["avx2"] is None and elsewhere["avx512f"] is None
    assert isinstance(elsewhere["cpu"], str)


def test_each_start_records_its_machine_and_another_kind_is_said(tmp_path, capsys):
    """Issue 26, numerics: machine.json lists each start of a run (CPU, its kernels,
    torch and numpy); a run resumed on another kind of CPU says so in one warning.
    config.json stays the settings alone (its strict comparison on resume holds)."""
    run_dir = tmp_path / "run"
    args = ["train", "smoke", "--total-env-steps", "640", "--run-dir", str(run_dir)]
    assert cli(args, capsys)[0] == 0
    (start,) = json.loads((run_dir / "machine.json").read_text())["starts"]
    assert (
        start["episode"] == 0 and start["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    )
    assert {"cpu", "avx2", "avx512f", "torch", "numpy", "platform"} <= set(start)
    start["cpu"], start["cpu_capability"] = "Another CPU", "AVX512"
    (run_dir / "machine.json").write_text(json.dumps({"starts": [start]}))
    code, _, err = cli(["train", "--resume", str(run_dir)], capsys)
    assert code == 0
    (warning,) = err.strip().splitlines()
    assert "another kind of machine (Another CPU, kernels AVX512" in warning
    starts = json.loads((run_dir / "machine.json").read_text())["starts"]
    assert [s["cpu"] for s in starts][0] == "Another CPU" and len(starts) == 2


@pytest.mark.parametrize(
    "args, meant, not_meant",
    [
        (["train", "quick", "--learning-rat", "1e-3"],
         "did you mean --learning-rate or --learning-rate-end-fraction?", "guided"),
        (["train", "quick", "--total-env-step", "5"], "did you mean --total-env-steps?", "paper"),
        (["train", "paper", "--torch-thread", "2"], "did you mean --torch-threads?", "smoke"),
        (["train", "smoke", "--teachr", "x"], "(see spikectl train smoke --help)", "--teacher"),
        (["contexts", "--n-trian", "3"], "did you mean --n-train?", "demo"),
    ],
)  # fmt: skip
def test_a_misspelt_flag_names_the_chosen_commands_nearest_flags(args, meant, not_meant, capsys):
    """Issue 26: tyro suggests the near flags of every preset, each with its help
    command; the line names only the chosen preset's, and its help command once."""
    code, _, err = cli(args, capsys)
    assert code == 2
    (line,) = err.strip().splitlines()
    assert meant in line and not_meant not in line
    assert line.count("--help") == 1
