"""Reliability round 4 (issue 40), class 5 at start-up: the environment Numba reads, and
Ctrl-C while the ``spikectl`` command is still loading.

``NUMBA_NUM_THREADS=0 spikectl --help`` was a ValueError traceback from inside
``import numba``, and a Ctrl-C while the command imported Numba or PyTorch a
KeyboardInterrupt traceback. The command's entry point (``_spikectl_launcher``) now
catches both around the import: one line, exit 2 or 130. ``import spikectl`` raises one
named error (``spikectl.environment_variables.EnvironmentVariableError``, a ValueError).
"""

from __future__ import annotations

import ast
import importlib.metadata
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from spikectl.environment_variables import (
    MAX_NUMBA_THREADS,
    EnvironmentVariableError,
    check_environment,
)

# What pip writes as the ``spikectl`` console script, for the entry point that the
# installed metadata names (checked below).
CONSOLE_SCRIPT = (
    "import re, sys\n"
    "from _spikectl_launcher import main\n"
    "sys.argv[0] = re.sub(r'(-script\\.pyw|\\.exe)?$', '', sys.argv[0])\n"
    "sys.exit(main())\n"
)

BAD_VALUES = [
    ("NUMBA_NUM_THREADS", "0"),
    ("NUMBA_NUM_THREADS", "-1"),
    ("NUMBA_NUM_THREADS", "four"),
    ("NUMBA_NUM_THREADS", ""),
    ("NUMBA_NUM_THREADS", str(MAX_NUMBA_THREADS + 1)),
    ("NUMBA_THREADING_LAYER", "bogus"),
    ("NUMBA_THREADING_LAYER_PRIORITY", "tbb omp"),
    ("NUMBA_DISABLE_JIT", "yes"),
]


def spikectl_command(*args: str, env: dict | None = None, **popen) -> subprocess.Popen:
    environment = {key: value for key, value in os.environ.items()
                   if not key.startswith("NUMBA_")}  # fmt: skip
    return subprocess.Popen(
        [sys.executable, "-c", CONSOLE_SCRIPT, *args],
        env={**environment, **(env or {})},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )


def test_the_console_script_enters_through_the_launcher():
    """The guarantees below hold for the installed ``spikectl`` command only if it
    enters through the launcher, outside the package."""
    (script,) = importlib.metadata.entry_points(group="console_scripts", name="spikectl")
    assert script.value == "_spikectl_launcher:main"
    import _spikectl_launcher

    tree = ast.parse(Path(_spikectl_launcher.__file__).read_text())
    modules = {alias.name for node in tree.body if isinstance(node, ast.Import)
               for alias in node.names}  # fmt: skip
    assert modules <= set(sys.stdlib_module_names), "the launcher imports only the stdlib"


@pytest.mark.parametrize(("name", "value"), BAD_VALUES)
def test_check_environment_names_the_variable(name, value):
    with pytest.raises(EnvironmentVariableError, match=f"{name}={value!r}") as caught:
        check_environment({name: value})
    assert isinstance(caught.value, ValueError)
    assert (caught.value.name, caught.value.value) == (name, value)


@pytest.mark.parametrize(
    "environ",
    [{}, {"NUMBA_NUM_THREADS": "1"}, {"NUMBA_NUM_THREADS": str(MAX_NUMBA_THREADS)},
     {"NUMBA_THREADING_LAYER": "Workqueue"}, {"NUMBA_DISABLE_JIT": "1"},
     {"NUMBA_THREADING_LAYER_PRIORITY": "omp workqueue tbb"}],
)  # fmt: skip
def test_check_environment_accepts_what_numba_uses(environ):
    check_environment(environ)


@pytest.mark.parametrize(
    ("name", "value"),
    [("NUMBA_NUM_THREADS", "0"), ("NUMBA_THREADING_LAYER", "bogus"), ("NUMBA_OPT", "fast")],
)
def test_a_bad_numba_variable_is_one_line_and_exit_2(name, value):
    """NUMBA_OPT is one spikectl does not check itself: Numba's own warning that it
    cannot parse a variable (which carries a traceback) becomes the refusal."""
    process = spikectl_command("--help", env={name: value})
    out, err = process.communicate(timeout=300)
    assert process.returncode == 2, err
    (line,) = err.splitlines()
    assert line.startswith(f"spikectl: error: the environment variable {name}={value!r}: ")
    assert out == ""


def test_import_spikectl_with_a_bad_numba_variable_raises_one_named_error():
    process = subprocess.run(
        [sys.executable, "-c",
         "try:\n"
         "    import spikectl\n"
         "except ValueError as error:\n"
         "    print(type(error).__module__, type(error).__name__, error)\n"],
        env={**os.environ, "NUMBA_NUM_THREADS": "0"},
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert process.returncode == 0 and process.stderr == "", process.stderr
    assert process.stdout.startswith(
        "spikectl.environment_variables EnvironmentVariableError the environment variable "
        "NUMBA_NUM_THREADS='0'"
    )


def test_a_threading_layer_that_cannot_start_is_named(monkeypatch):
    """NUMBA_THREADING_LAYER=tbb without TBB: a ValueError from inside the first threaded
    kernel call, now one EnvironmentVariableError before it."""
    import numba
    import numpy as np

    from spikectl.neuron import simulator

    def no_layer():
        raise ValueError("No threading layer could be loaded.\nHINT: Intel TBB is required")

    monkeypatch.setattr(numba, "get_num_threads", no_layer)
    monkeypatch.setattr(simulator, "_threads_started", False)
    monkeypatch.setenv("NUMBA_THREADING_LAYER", "tbb")
    weights = np.zeros((simulator.PARALLEL_MIN_BATCH, 8, 8), dtype=np.int8)
    actions = np.zeros((simulator.PARALLEL_MIN_BATCH, 128), dtype=np.int64)
    with pytest.raises(EnvironmentVariableError, match="NUMBA_THREADING_LAYER='tbb'.*TBB"):
        simulator.simulate(weights, actions)


# Libraries the command loads, by a file each maps into memory: a Ctrl-C is sent as soon
# as that file is mapped, i.e. while that library is being imported.
LOADING = {
    "numpy": "_multiarray_umath",
    "numba": "numba/_helperlib",
    "torch": "libtorch_cpu",
}


@pytest.mark.parametrize("library", list(LOADING))
def test_ctrl_c_while_the_command_loads_is_one_line_and_130(library):
    """A Ctrl-C while ``spikectl --help`` imports numpy, Numba or PyTorch."""
    process = spikectl_command(
        "--help",
        # As in a terminal: a test run started in the background ignores SIGINT.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    maps = Path(f"/proc/{process.pid}/maps")
    deadline = time.monotonic() + 120
    while LOADING[library] not in maps.read_text():
        assert process.poll() is None, f"the command ended before it loaded {library}"
        assert time.monotonic() < deadline, f"{library} not loaded within 120 s"
        time.sleep(0.002)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert err == "spikectl: interrupted while starting (nothing was run)\n"
    assert out == ""


@pytest.mark.parametrize("delay_s", [0.0, 0.3, 1.0])
def test_ctrl_c_at_any_moment_after_python_started_is_one_line(delay_s):
    """Once the launcher runs (its import of the command is under way: numpy mapped),
    a Ctrl-C at any later moment is one line and 130, or --help has finished."""
    process = spikectl_command(
        "--help", preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)
    )
    maps = Path(f"/proc/{process.pid}/maps")
    while process.poll() is None and LOADING["numpy"] not in maps.read_text():
        time.sleep(0.002)
    time.sleep(delay_s)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    if process.returncode == 0:  # finished first
        assert err == "" and "usage: spikectl" in out
    else:
        assert process.returncode == 130, err
        assert len(err.splitlines()) == 1 and err.startswith("spikectl: interrupted"), err


# A stand-in for an extension module that, interrupted while it initialises, replaces the
# KeyboardInterrupt with an error of its own and no chain back to it (numpy does so on
# Python 3.10: "PyCapsule_Import could not import module 'datetime'").
SWALLOWING_IMPORT = (
    "import os, signal\n"
    "try:\n"
    "    os.kill(os.getpid(), signal.SIGINT)\n"
    "    import time; time.sleep(5)\n"
    "except BaseException:\n"
    "    pass\n"
    "raise ImportError('could not import module \"datetime\"')\n"
)


# A Ctrl-C that lands while Python runs a weak reference's callback (importlib's module
# locks use them): Python can only print it as "Exception ignored" and go on.
INTERRUPTED_CALLBACK = (
    "import os, signal, time, weakref\n"
    "class Held: pass\n"
    "def callback(reference):\n"
    "    os.kill(os.getpid(), signal.SIGINT)\n"
    "    time.sleep(5)\n"
    "held = Held()\n"
    "reference = weakref.ref(held, callback)\n"
    "del held\n"
)


INTERRUPTED_STARTING_LINE = "spikectl: interrupted while starting (nothing was run)\n"
INTERRUPTED_LINE = "spikectl: interrupted\n"


def run_stand_in(tmp_path, where: str, module: str, code: str, then: str = "") -> tuple:
    """(exit code, stderr, stdout) of the launcher running ``spikectl --help`` on a
    stand-in package whose ``spikectl.cli`` runs ``code`` while it is imported (``where``
    "spikectl.cli"), or whose command imports ``module`` holding it (``"the command"``);
    ``then`` is the command's body after that."""
    package = tmp_path / "spikectl"
    (package / "cli").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    if where == "spikectl.cli":
        (package / "cli" / "__init__.py").write_text(code + f"def main():\n    pass{then}\n")
    else:  # a library the command imports only when it runs
        (package / "cli" / "__init__.py").write_text(f"def main():\n    import {module}{then}\n")
        (tmp_path / f"{module}.py").write_text(code)
    launcher = Path(__file__).resolve().parents[1]
    process = spikectl_command(
        "--help",
        env={"PYTHONPATH": os.pathsep.join([str(tmp_path), str(launcher)])},
        cwd=tmp_path,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    out, err = process.communicate(timeout=60)
    return process.returncode, err, out


@pytest.mark.parametrize("where", ["spikectl.cli", "the command"])
def test_ctrl_c_in_a_callback_is_still_one_line(tmp_path, where):
    """A Ctrl-C Python could only report from a callback: no "Exception ignored" text,
    and the launcher's one line and 130 once the import or the command returns."""
    code, err, out = run_stand_in(tmp_path, where, "interrupted_callback", INTERRUPTED_CALLBACK,
                                  then="\n    print('usage: spikectl')")  # fmt: skip
    expected = INTERRUPTED_STARTING_LINE if where == "spikectl.cli" else INTERRUPTED_LINE
    assert (code, err) == (130, expected)
    assert out in ("", "usage: spikectl\n")


@pytest.mark.parametrize("where", ["spikectl.cli", "the command"])
def test_ctrl_c_an_import_turned_into_another_error_is_still_one_line(tmp_path, where):
    """The launcher knows a Ctrl-C by its signal, whatever error the import left."""
    outcome = run_stand_in(tmp_path, where, "swallowing", SWALLOWING_IMPORT)
    expected = INTERRUPTED_STARTING_LINE if where == "spikectl.cli" else INTERRUPTED_LINE
    assert outcome == (130, expected, "")
