"""Reliability round 4 (issue 40), what commands write and the options they take.

Class 7: an output path that names a run's own file, an existing device, FIFO or link,
or the other output, is refused before any work (nothing overwritten). Class 8: results
are written even when the reader of standard output has gone (``| head -1``). Class 9:
options are honoured or refused (``--model best`` without a run, ``--rate-hz inf``,
``--torch-threads 1000``, ``--random-seeds 10^8``, ``--task`` beside ``--resume``, the
task's episode length). Class 5: Ctrl-C inside a Numba kernel, inside a C library's
callback, and while exiting. Class 13: a file name is never reported as a flag.
"""

from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from spikectl.cli import main
from spikectl.files import FileWriteError, atomic_write_text

SMOKE_RUN = Path(__file__).parent / "data" / "format2-smoke-run"


def cli(args: list, capsys) -> tuple[int, str, str]:
    try:
        main([str(arg) for arg in args])
        code = 0
    except SystemExit as exit:
        code = exit.code
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line(err: str) -> str:
    (line,) = err.strip().splitlines()
    assert line.startswith("spikectl: error:")
    return line


@pytest.fixture
def run_copy(tmp_path) -> Path:
    run = tmp_path / "run"
    shutil.copytree(SMOKE_RUN, run)
    return run


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


@pytest.mark.parametrize("name", ["checkpoint.pt", "config.json", "metrics.csv",
                                  "test_contexts.npz", "best_model.pt"])  # fmt: skip
@pytest.mark.parametrize(
    "command",
    [
        ["benchmark", "do-nothing", "--task", "paper", "--out"],
        ["benchmark", "do-nothing", "--task", "paper", "--per-network"],
        ["realtime", "do-nothing", "--episodes", "1", "--out"],
    ],
)
def test_an_output_naming_a_runs_own_file_is_refused(run_copy, name, command, capsys):
    """Class 7: ``--per-network RUN/checkpoint.pt`` destroyed the run's checkpoint."""
    before = snapshot(run_copy)
    code, _, err = cli([*command, run_copy / name], capsys)
    assert code == 2 and "that is a file of the run" in one_line(err)
    assert snapshot(run_copy) == before


@pytest.mark.parametrize("kind", ["fifo", "device", "link"])
@pytest.mark.parametrize("command", [["benchmark", "do-nothing", "--task", "paper", "--out"],
                                     ["realtime", "do-nothing", "--episodes", "1", "--out"]])
def test_an_output_that_is_not_a_regular_file_is_refused(tmp_path, kind, command, capsys):
    """Class 7: the writer replaced a device node, FIFO or symlink with a file."""
    if kind == "fifo":
        path = tmp_path / "pipe"
        os.mkfifo(path)
    elif kind == "device":
        path = Path("/dev/null")
    else:
        (tmp_path / "target.csv").write_text("kept\n")
        path = tmp_path / "link.csv"
        path.symlink_to(tmp_path / "target.csv")
    code, _, err = cli([*command, path], capsys)
    line = one_line(err)
    assert code == 2 and ("not a regular file" in line or "symbolic link" in line)
    assert path.is_symlink() or not path.is_file()
    if kind == "link":
        assert (tmp_path / "target.csv").read_text() == "kept\n"


def test_the_atomic_writer_never_replaces_a_link_or_a_fifo(tmp_path):
    """Class 7, the API: atomic_write refuses what renaming over would destroy."""
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    for name in ("pipe", "link"):
        with pytest.raises(FileWriteError, match="not a regular file; refusing to replace it"):
            atomic_write_text(tmp_path / name, "x")
    assert (tmp_path / "link").is_symlink() and not (tmp_path / "elsewhere").exists()


def test_two_outputs_naming_one_file_are_refused(tmp_path, capsys):
    """Class 7: --out and --per-network given one path clobbered each other."""
    out = tmp_path / "o.csv"
    code, _, err = cli(["benchmark", "do-nothing", "--task", "paper", "--out", out,
                        "--per-network", tmp_path / "." / "o.csv"], capsys)  # fmt: skip
    assert code == 2 and "name the same file" in one_line(err)
    assert not out.exists()


def test_results_are_written_when_the_reader_of_stdout_goes_away(tmp_path):
    """Class 8: ``spikectl benchmark ... --out o.csv | head -1`` exited 141 without
    writing o.csv. The files are written, then the command stops quietly."""
    out, per = tmp_path / "o.csv", tmp_path / "p.csv"
    read, write = os.pipe()
    process = subprocess.Popen(
        [sys.executable, "-m", "spikectl.cli", "benchmark", "do-nothing", "--task", "paper",
         "n16", "--out", str(out), "--per-network", str(per)],
        stdout=write, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    os.close(write)
    with os.fdopen(read) as reader:
        assert reader.readline().startswith("benchmark suite")
    _, err = process.communicate(timeout=300)
    assert process.returncode == 141 and err == ""
    assert len(out.read_text().splitlines()) == 3  # the header and two tasks
    assert len(per.read_text().splitlines()) == 201


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["benchmark", "do-nothing", "--task", "paper", "--random-seeds", "100000000"],
         "--random-seeds must be an integer in 1..1000, got 100000000"),
        (["benchmark", "random", "--task", "paper", "--torch-threads", "1000"],
         "--torch-threads must be an integer in 1..256"),
        (["benchmark", "do-nothing", "--task", "paper", "--model", "best"],
         "--model chooses among a run directory's networks"),
        (["benchmark", "do-nothing", "--task", "paper", "--compiled"],
         "--compiled chooses among a run directory's networks"),
        (["realtime", "do-nothing", "--rate-hz", "inf"],
         "--rate-hz must be a number in (0, 1e+06]"),
        (["realtime", "do-nothing", "--rate-hz", "nan"], "--rate-hz must be a number in"),
        (["realtime", "do-nothing", "--torch-threads", "1000"], "--torch-threads must be an"),
        (["train", "--resume", "RUN", "--task", "paper"], "--task paper starts a run on"),
    ],
)
def test_options_out_of_range_or_without_effect_are_refused(args, message, capsys):
    """Class 9: options that were accepted and then ignored or lied about."""
    code, _, err = cli(args, capsys)
    assert code == 2 and message in one_line(err)


def test_model_best_with_a_policy_file_is_refused_in_the_api(tmp_path):
    """Class 9: ``--model best`` with a .npz played the file's one network as "best"."""
    from spikectl.agents import export_policy, make_agent
    from spikectl.training.loaders import load_controller

    path = export_policy(make_agent("tdrqn", 5, 20), tmp_path / "policy.npz")
    with pytest.raises(ValueError, match="model='best' chooses among a run directory's"):
        load_controller(path, model="best")
    with pytest.raises(ValueError, match="compiled=True chooses"):
        load_controller("do-nothing", compiled=True)
    assert load_controller(path).spec.n_neurons == 5


def test_a_task_trains_on_its_own_episode_length():
    """Class 9: ``train smoke --task paper`` trained on 20-step sets (the preset's), not
    the task's pinned 60-step ones, and benchmark refused the run only afterwards."""
    from spikectl.cli.training import parse_train
    from spikectl.experiments import suite

    command = parse_train(["smoke", "--task", "paper"])
    assert command.config.env.episode_length == suite.suite_version(1).episode_length == 60
    assert command.config.env.n_train == suite.suite_version(1).set_size


def benchmark_all_in_a_child() -> subprocess.Popen:
    """``spikectl.cli.main(["benchmark", "do-nothing", "--task", "all"])`` in a child
    process, returned once its first line is out (Numba and the command loaded)."""
    process = subprocess.Popen(
        [sys.executable, "-c",
         "from spikectl.cli import main\n"
         "import spikectl.planning.beam as beam\n"
         "print('ready', flush=True)\n"
         "main(['benchmark', 'do-nothing', '--task', 'all'])\n"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # As in a terminal: a test run started in the background (`pytest &`, some CI
        # runners) ignores SIGINT, and a child would inherit that and never see Ctrl-C.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    assert process.stdout.readline().strip() == "ready"
    assert process.stdout.readline().startswith("benchmark suite")
    return process


def test_ctrl_c_inside_a_numba_kernel_is_one_line_and_130(tmp_path):
    """Class 5: Ctrl-C while the oracle's beam search runs (Numba) was a SystemError
    traceback and exit 1."""
    process = benchmark_all_in_a_child()
    time.sleep(2.0)  # into the references' planning (Numba) of the first task
    # Numba's dispatcher may clear a pending interrupt (it calls PyErr_Clear in some
    # paths), so, like a user, press Ctrl-C again until the command stops.
    for _ in range(6):
        process.send_signal(signal.SIGINT)
        try:  # exiting takes well under 10 s: a second press never lands in the exit
            process.wait(timeout=10.0)
            break
        except subprocess.TimeoutExpired:
            continue
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert err.strip().splitlines() == [err.strip()] and "interrupted" in err


def test_a_second_ctrl_c_while_exiting_changes_nothing():
    """Class 5: a second Ctrl-C while the process shut down (about a second with
    PyTorch and Numba loaded) ended it by the signal (exit -2) instead of 130; under
    load it once crashed a half-finalised module (SIGSEGV). A caller that catches the
    SystemExit keeps its Ctrl-C (next test)."""
    process = benchmark_all_in_a_child()
    time.sleep(1.0)
    for _ in range(6):  # as in the test above: a press inside a kernel call may be cleared
        process.send_signal(signal.SIGINT)
        if select.select([process.stderr], [], [], 10.0)[0]:  # the exit has begun
            break
    first_line = process.stderr.readline()  # written as the exit begins
    time.sleep(0.2)  # into the interpreter's shutdown, which takes about a second
    process.send_signal(signal.SIGINT)  # a no-op if the process has already gone
    rest = process.stderr.read()
    process.wait(timeout=120)
    assert "interrupted" in first_line and rest == "", rest
    assert process.returncode == 130


def run_as_benchmark(command, monkeypatch, capsys) -> tuple[int, str]:
    """``main(["benchmark", "do-nothing"])`` with ``command`` in the benchmark's place."""
    import spikectl.cli as spikectl_cli
    from spikectl.cli.benchmark import BenchmarkCommand

    monkeypatch.setitem(spikectl_cli.COMMANDS, "benchmark", (command, BenchmarkCommand))
    code, _, err = cli(["benchmark", "do-nothing"], capsys)
    return code, err


def test_a_caller_that_catches_the_exit_keeps_its_ctrl_c(monkeypatch, capsys):
    """Ignoring a second Ctrl-C is for the process's shutdown only: a notebook or a docs
    build that catches the SystemExit still stops on the next one."""

    def interrupted(command):
        raise KeyboardInterrupt

    before = signal.getsignal(signal.SIGINT)
    code, err = run_as_benchmark(interrupted, monkeypatch, capsys)
    assert code == 130 and "interrupted" in err
    assert signal.getsignal(signal.SIGINT) is before


@pytest.fixture
def python_handles_sigint():
    """SIGINT raises KeyboardInterrupt, as in a terminal: the redelivery simulates SIGINT,
    which reaches Python only where Python handles it (a test run started in the
    background ignores SIGINT)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@pytest.mark.parametrize("carries_on", [True, False], ids=["carries-on", "returns"])
def test_a_ctrl_c_lost_in_a_callback_still_stops_the_command(
    carries_on, python_handles_sigint, monkeypatch, capsys
):
    """Class 5, deterministically: a Ctrl-C that lands while a C library calls back into
    Python was printed as "Exception ignored on calling ctypes callback function" and the
    command carried on to its end. Now it stops the command, or, if the command returns
    first, its end: one line, 130."""
    import ctypes

    from spikectl.cli.interrupts import INTERRUPTED

    compare_type = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)

    def compare(left, right):
        raise KeyboardInterrupt  # as if the signal's handler ran here

    finished = []

    def interrupted_in_a_callback(command):
        values = (ctypes.c_int * 2)(2, 1)
        ctypes.CDLL(None).qsort(values, 2, ctypes.sizeof(ctypes.c_int), compare_type(compare))
        for _ in range(300 if carries_on else 0):  # 3 s of work after the callback
            time.sleep(0.01)
        finished.append(command)

    code, err = run_as_benchmark(interrupted_in_a_callback, monkeypatch, capsys)
    assert code == 130 and err.splitlines() == [INTERRUPTED]
    assert len(finished) == (0 if carries_on else 1)


def test_a_ctrl_c_waits_for_llvmlite(python_handles_sigint, monkeypatch, capsys):
    """Class 5: a Ctrl-C while Numba compiled (Python 3.13 in CI, the double-press test)
    was lost in llvmlite's object-cache callback, or left the compiler half-built
    (RuntimeError "no compiled object yet for <Library '_advance_kernel'>", exit 1), or
    crashed the process as it exited (SIGSEGV). Now llvmlite's call finishes and the
    Ctrl-C stops the command as soon as it has returned."""
    from spikectl.cli.interrupts import INTERRUPTED

    llvmlite = {"__name__": "llvmlite.binding.in_a_test"}  # code of the llvmlite package
    exec(  # noqa: S102 - a function whose frames are llvmlite's
        "def finalize_object(compiled):\n"
        "    import _thread, time\n"
        "    _thread.interrupt_main()  # Ctrl-C, 0.2 s before llvmlite returns\n"
        "    for _ in range(20):\n"
        "        time.sleep(0.01)\n"
        "    compiled.append(True)\n",
        llvmlite,
    )  # fmt: skip
    compiled, ran_on = [], []

    def compiles_then_runs(command):
        llvmlite["finalize_object"](compiled)
        for _ in range(300):  # 3 s of the command after llvmlite
            time.sleep(0.01)
        ran_on.append(command)

    code, err = run_as_benchmark(compiles_then_runs, monkeypatch, capsys)
    assert code == 130 and err.splitlines() == [INTERRUPTED]
    assert compiled == [True] and ran_on == []
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored


def test_a_system_error_caused_by_ctrl_c_is_the_interrupt(monkeypatch, capsys):
    """Class 5, deterministically: Numba returns a KeyboardInterrupt raised inside a
    kernel as a SystemError caused by it; any other SystemError keeps its traceback."""

    def numba_interrupted(command):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise SystemError("CPUDispatcher returned a result with an exception set") from (
                interrupt
            )

    code, err = run_as_benchmark(numba_interrupted, monkeypatch, capsys)
    assert code == 130 and err.startswith("spikectl: interrupted") and len(err.splitlines()) == 1

    def a_bug(command):
        raise SystemError("a real bug")

    with pytest.raises(SystemError, match="a real bug"):
        run_as_benchmark(a_bug, monkeypatch, capsys)


def test_a_file_name_is_never_reported_as_a_flag():
    """Class 13: ``evaluate RUN --contexts test_contexts.npz`` reported
    ``--test-contexts.npz: ...``, a flag that does not exist."""
    from spikectl.cli import COMMANDS
    from spikectl.cli.errors import flag_message

    kinds = [kind for _, kind in COMMANDS.values()]
    assert flag_message("test_contexts.npz is damaged", kinds) == "test_contexts.npz is damaged"
    assert flag_message("train_contexts/x.npz: gone", kinds) == "train_contexts/x.npz: gone"
    assert flag_message("n_test must be >= 1", kinds) == "--n-test must be >= 1"


# Round 5 (issue 58), class "lost": an existing file is never replaced without
# --overwrite, another input's output never lands on this one's, and two writers of one
# file at once are refused.

QUICK_OUTPUTS = [
    ["benchmark", "do-nothing", "--task", "paper", "--out"],
    ["benchmark", "do-nothing", "--task", "paper", "--per-network"],
    ["realtime", "do-nothing", "--episodes", "1", "--out"],
]


@pytest.mark.parametrize("command", QUICK_OUTPUTS)
def test_an_existing_output_is_kept_without_overwrite(tmp_path, command, capsys):
    """``--out FILE`` replaced an existing ordinary file and exited 0."""
    path = tmp_path / "mine.csv"
    path.write_text("a file of the user\n")
    code, _, err = cli([*command, path], capsys)
    line = one_line(err)
    assert code == 2 and f"{command[-1]}: {path} exists: pass --overwrite" in line
    assert path.read_text() == "a file of the user\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.csv"]  # no lock left


def test_overwrite_replaces_the_file_and_leaves_no_lock(tmp_path, capsys):
    path = tmp_path / "d.csv"
    path.write_text("old\n")
    code, out, _ = cli(["realtime", "do-nothing", "--episodes", "1", "--out", path,
                        "--overwrite"], capsys)  # fmt: skip
    assert code == 0 and f"wrote {path}" in out
    assert path.read_text().startswith("episode,step,latency_ms,missed\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv"]


def test_a_second_writer_of_one_output_is_refused_naming_the_first(tmp_path, capsys):
    """Two benchmarks on one --out at once: the last writer's rows replaced the first's."""
    from spikectl.locks import output_lock

    out = tmp_path / "new" / "o.csv"
    with output_lock(tmp_path / "new" / "." / "o.csv", "--out"):  # the first, mid-run
        code, _, err = cli(["benchmark", "do-nothing", "--task", "paper", "--out", out], capsys)
        line = one_line(err)
        assert code == 2 and f"another process (pid {os.getpid()}) is writing" in line
        assert not out.exists()
    assert not (tmp_path / "new").exists()  # the folder made for the lock is gone again


def test_a_lock_left_by_a_dead_process_does_not_block(tmp_path, capsys):
    """The lock is flock(2): the kernel drops it with its process, whatever the file says."""
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True)  # fmt: skip
    (tmp_path / ".d.csv.lock").write_text(child.stdout)  # a pid that has ended
    code, _, err = cli(["realtime", "do-nothing", "--episodes", "1", "--out",
                        tmp_path / "d.csv"], capsys)  # fmt: skip
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv"]


def test_the_lock_is_released_on_ctrl_c(tmp_path):
    from spikectl.cli.output import claimed_outputs
    from spikectl.locks import output_lock

    out = tmp_path / "o.csv"
    with pytest.raises(KeyboardInterrupt):
        with claimed_outputs([("--out", out)], overwrite=False):
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    with output_lock(out, "--out"):  # free again
        pass


def test_a_lock_held_by_another_process_refuses(tmp_path):
    """The same, across processes: a child holds the lock while this one asks for it."""
    from spikectl.locks import OutputBusyError, output_lock

    out = tmp_path / "o.csv"
    child = subprocess.Popen(
        [sys.executable, "-c", "import sys; from spikectl.locks import output_lock\n"
         f"with output_lock({str(out)!r}, '--out'):\n    print('held', flush=True)\n"
         "    sys.stdin.readline()\n"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert child.stdout.readline() == "held\n"
        with pytest.raises(OutputBusyError, match=rf"--out {out}: another process \(pid "
                           rf"{child.pid}\) is writing that file"):  # fmt: skip
            with output_lock(out, "--out"):
                pass
    finally:
        child.communicate("\n", timeout=60)
    with output_lock(out, "--out"):  # released with the child's block
        pass


def test_the_atomic_writer_without_replace_keeps_a_file_made_meanwhile(tmp_path):
    path = tmp_path / "o.csv"

    def write(handle):
        path.write_text("made meanwhile\n")  # another program, while the rows are written
        handle.write(b"rows\n")

    from spikectl.files import atomic_write

    with pytest.raises(FileWriteError, match="appeared while this command ran; it is kept"):
        atomic_write(path, write, replace=False)
    assert path.read_text() == "made meanwhile\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.csv"]
    atomic_write(tmp_path / "new.csv", lambda handle: handle.write(b"rows\n"), replace=False)
    assert (tmp_path / "new.csv").read_bytes() == b"rows\n"


def test_baselines_of_another_input_never_land_on_the_default_table(tmp_path, monkeypatch,
                                                                    capsys):  # fmt: skip
    """``baselines --contexts OTHER.npz`` wrote over the default split's baselines.csv."""
    from spikectl.cli.baseline_policies import BaselinesCommand, default_out
    from spikectl.contexts import make_splits

    assert default_out(BaselinesCommand()) == Path("runs/baselines/baselines.csv")
    for changed, name in (
        ({"contexts": Path("sets/ctx.npz")}, "baselines-ctx.csv"),
        ({"split": "train"}, "baselines-train.csv"),
        ({"env": "spikectl/NeuronControlNoisy-v0"}, "baselines-NeuronControlNoisy-v0.csv"),
        ({"observation_noise_mV": 0.5}, "baselines-noise0.5mV.csv"),
        ({"hidden_fraction": 0.25, "split": "validation"}, "baselines-validation-hidden0.25.csv"),
    ):
        assert default_out(BaselinesCommand(**changed)) == Path("runs/baselines") / name
    monkeypatch.chdir(tmp_path)
    make_splits(3, 3, 5, 20, seed=4)[1].save("ctx.npz")
    kept = Path("runs/baselines/baselines.csv")
    kept.parent.mkdir(parents=True)
    kept.write_text("the default split's table\n")
    quick = ["--random-seeds", "2", "--oracle-width", "4", "--identify-width", "2"]
    code, out, err = cli(["baselines", "--contexts", "ctx.npz", *quick], capsys)
    assert code == 0, err
    assert "wrote runs/baselines/baselines-ctx.csv" in out
    assert kept.read_text() == "the default split's table\n"
    assert len(Path("runs/baselines/baselines-ctx.csv").read_text().splitlines()) == 4
    code, _, err = cli(["baselines", "--contexts", "ctx.npz", *quick], capsys)
    assert code == 2 and "--out: runs/baselines/baselines-ctx.csv exists" in one_line(err)


def test_demo_and_plot_keep_an_earlier_run_s_files(tmp_path, capsys):
    """The same rule for the commands that write a folder of files."""
    demo = tmp_path / "demo"
    demo.mkdir()
    (demo / "results.json").write_text("kept\n")
    code, _, err = cli(["demo", "--out-dir", demo, "--n-train", "3", "--n-test", "3"], capsys)
    assert code == 2 and "results.json exist(s): pass --overwrite" in one_line(err)
    assert (demo / "results.json").read_text() == "kept\n"
    assert not (demo / "train_contexts.npz").exists()
    figures = tmp_path / "sweep" / "figures"
    figures.mkdir(parents=True)
    (figures / "figure4.png").write_text("kept\n")
    code, _, err = cli(["plot", tmp_path / "sweep"], capsys)
    assert code == 2 and "figure4.png exist(s): pass --overwrite" in one_line(err)
    assert (figures / "figure4.png").read_text() == "kept\n"


def test_plot_of_a_file_names_what_the_file_is(tmp_path, capsys):
    """`spikectl plot ctx.npz` said "cannot create the folder ctx.npz/figures"."""
    from spikectl.contexts import ContextSet

    ContextSet.generate(2, n_neurons=4, episode_length=10, seed=0).save(tmp_path / "ctx.npz")
    code, _, err = cli(["plot", tmp_path / "ctx.npz"], capsys)
    line = one_line(err)
    assert code == 2 and "context set" in line and "takes a sweep directory" in line, line
    (tmp_path / "notes.txt").write_text("a user's notes\n")
    code, _, err = cli(["plot", tmp_path / "notes.txt"], capsys)
    assert code == 2 and "notes.txt is a file; spikectl plot takes" in one_line(err)
    assert (tmp_path / "notes.txt").read_text() == "a user's notes\n"


def written_files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")
            if p.is_file() and p.name != ".spikectl.lock"}  # fmt: skip


def test_the_guarded_names_are_every_file_demo_and_plot_write(tmp_path, capsys):
    """The refusal checks a list of names: it must hold everything the command writes."""
    from spikectl.cli.context_sets import DEMO_FILES
    from spikectl.cli.runs import PLOT_FILES

    code, _, err = cli(["demo", "--out-dir", tmp_path / "demo", "--n-train", "3",
                        "--n-test", "3"], capsys)  # fmt: skip
    assert code == 0, err
    assert written_files(tmp_path / "demo") == set(DEMO_FILES)
    shutil.copytree(SMOKE_RUN, tmp_path / "sweep" / "trials" / "t0")
    code, _, err = cli(["plot", tmp_path / "sweep"], capsys)
    assert code == 0, err
    figures = tmp_path / "sweep" / "figures"
    assert written_files(figures) and written_files(figures) <= set(PLOT_FILES)
    before = {name: (figures / name).read_bytes() for name in written_files(figures)}
    code, _, err = cli(["plot", tmp_path / "sweep"], capsys)
    assert code == 2 and "pass --overwrite" in one_line(err)
    assert {name: (figures / name).read_bytes() for name in before} == before
    code, _, err = cli(["plot", tmp_path / "sweep", "--overwrite"], capsys)
    assert code == 0, err
