"""Ctrl-C at random moments into a command that compiles Numba kernels, repeated.

Each trial runs ``spikectl.cli.main(["benchmark", "do-nothing", "--task", "all"])`` in a
child process with an empty Numba cache (``NUMBA_CACHE_DIR``, so the first seconds are
spent compiling), sends one SIGINT at a uniform random delay in [0, MAX_DELAY_S) after the
command has loaded, and classifies the outcome:

- ``ok``: exit 130 and exactly one line on stderr, "spikectl: interrupted ...";
- ``garbled``: any other exit or stderr (a traceback, "Exception ignored ...", a crash);
- ``lost``: still running ``WAIT_S`` after the press (the Ctrl-C had no effect); it is
  then pressed again until it stops, and its output is classified as above too.

Run: ``python benchmarks/ctrl_c_while_compiling.py [--trials 40] [--seed 0]
[--python PYTHON] [--source DIR] [--launcher]`` (PYTHON: the interpreter whose spikectl is
tested; DIR: a checkout whose ``spikectl`` package the child imports instead of the
installed one, to compare two commits with one environment; ``--launcher``: enter
through ``_spikectl_launcher.main``, as the installed ``spikectl`` script does, with its
SIGINT handler). Prints each trial that is not ``ok``
and the counts; exits 1 unless every trial is ``ok``.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time

MAX_DELAY_S = 4.0
WAIT_S = 8.0
CHILD = """\
import os, sys
source = os.environ.get("SPIKECTL_SOURCE")
if source:  # this checkout's package, not the installed (editable) one
    sys.meta_path[:] = [finder for finder in sys.meta_path if "editable" not in repr(finder)]
    sys.path.insert(0, source)
from spikectl.cli import main
import spikectl
assert not source or spikectl.__file__.startswith(source), spikectl.__file__
print("ready", flush=True)
if os.environ.get("THROUGH_LAUNCHER"):  # as the installed spikectl script enters
    import _spikectl_launcher
    sys.argv = ["spikectl", "benchmark", "do-nothing", "--task", "all"]
    _spikectl_launcher.main()
else:
    main(["benchmark", "do-nothing", "--task", "all"])
"""


def one_trial(python: str, source: str | None, delay_s: float, launcher: bool) -> tuple[str, str]:
    """The outcome of one Ctrl-C ``delay_s`` after the command loaded, and its stderr."""
    environment = dict(os.environ, NUMBA_CACHE_DIR=tempfile.mkdtemp())
    if source:
        environment["SPIKECTL_SOURCE"] = source
    if launcher:
        environment["THROUGH_LAUNCHER"] = "1"
    child = subprocess.Popen(
        [python, "-c", CHILD], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=environment,
        # As in a terminal: a job started in the background ignores SIGINT.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    if child.stdout.readline().strip() != "ready":
        child.kill()
        return "garbled", child.communicate()[1]
    time.sleep(delay_s)
    child.send_signal(signal.SIGINT)
    lost = False
    try:
        child.wait(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        lost = True
        while child.poll() is None:
            child.send_signal(signal.SIGINT)
            try:
                child.wait(timeout=WAIT_S)
            except subprocess.TimeoutExpired:
                continue
    err = child.communicate()[1]
    lines = err.strip().splitlines()
    clean = child.returncode == 130 and len(lines) == 1 and "interrupted" in lines[0]
    if not clean:
        return "garbled", f"exit {child.returncode}: {err.strip()[-2000:]}"
    return ("lost" if lost else "ok"), err


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0, help="seeds the delays")
    parser.add_argument("--python", default=sys.executable)
    parser.add_argument("--source", default=None, help="a checkout to import spikectl from")
    parser.add_argument("--launcher", action="store_true", help="enter as the spikectl script does")
    args = parser.parse_args()
    delays = random.Random(args.seed)
    counts = {"ok": 0, "garbled": 0, "lost": 0}
    for trial in range(args.trials):
        delay_s = delays.uniform(0.0, MAX_DELAY_S)
        outcome, err = one_trial(args.python, args.source, delay_s, args.launcher)
        counts[outcome] += 1
        if outcome != "ok":
            print(f"trial {trial}, Ctrl-C at {delay_s:.2f} s: {outcome}\n{err}", flush=True)
    print(", ".join(f"{count} {outcome}" for outcome, count in counts.items())
          + f" of {args.trials} trials")  # fmt: skip
    raise SystemExit(0 if counts["ok"] == args.trials else 1)


if __name__ == "__main__":
    main()
