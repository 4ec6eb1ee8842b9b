"""The hostile-input probes of reliability round 4 (issue 40), kept so they can be rerun.

Each probe is one command line (or one Python API call) a hostile but realistic user
might try, in a fresh folder holding a copy of a small finished run (``RUN``), a
compiled policy (``pol.npz``) and a context set (``ctx.npz``). Each is classified:

- ``ok``: refused in one line naming the problem (exit 2 on the command line, a named
  exception in the API), or run as asked where the input is legitimate; nothing lost;
- ``traceback``: a Python traceback on stderr;
- ``silent``: accepted (exit 0) where it should have been refused, or a wrong result;
- ``hang``: not finished within the time limit (a FIFO read forever, a runaway size);
- ``lost``: a file that must survive changed or vanished, or a result not written.

Run: ``python benchmarks/hostile_inputs_round4.py [--python PYTHON] [--only WORD]``
(PYTHON: the interpreter of the spikectl to probe; default this one). Prints one line per
probe and the counts; exits 1 if any probe is not ``ok``. Class 3 (type errors in sweep
files and learner settings) is probed elsewhere (issue 41).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SMOKE_RUN = REPO / "tests" / "data" / "format2-smoke-run"
TIMEOUT_S = 180

REFUSE, RUN = "refuse", "run"


@dataclass(frozen=True)
class Probe:
    name: str
    klass: int
    setup: str
    """Shell commands run in the probe's folder first ('' for none)."""
    command: list[str] | str
    """spikectl's arguments, or Python code (a str) that must raise or print."""
    expect: str = REFUSE
    keep: tuple[str, ...] = ()
    """Files (relative to the folder) that must be byte-identical afterwards."""
    makes: tuple[str, ...] = ()
    """Files that must exist afterwards."""
    pipe_head: bool = False
    """Read one line of stdout and close the pipe (``| head -1``)."""
    env: dict = field(default_factory=dict)


RUN_FILES = ("RUN/config.json", "RUN/checkpoint.pt", "RUN/metrics.csv", "RUN/best_model.pt")
CKPT_FIFO = "rm -f RUN/checkpoint.pt && mkfifo RUN/checkpoint.pt"
CKPT_ZERO = "rm -f RUN/checkpoint.pt && ln -s /dev/zero RUN/checkpoint.pt"
CKPT_DIR = "rm -f RUN/checkpoint.pt && mkdir RUN/checkpoint.pt"
POLICY = "from spikectl.agents.compiled import CompiledPolicy, PolicyFileError\n"
HEADER = (
    "import json, numpy as np\n"
    "d = np.load('pol.npz'); a = {k: d[k] for k in d.files}\n"
    "h = json.loads(str(a['metadata'])); h.update(CHANGE); "
    "a['metadata'] = np.array(json.dumps(h)); np.savez('bad.npz', **a)\n"
)


def header_probe(name: str, klass: int, change: str) -> Probe:
    return Probe(name, klass, "", POLICY + HEADER.replace("CHANGE", change)
                 + "CompiledPolicy.load('bad.npz')\n")  # fmt: skip


def controller_probe(name: str, who: str, change: str) -> Probe:
    code = (
        "import numpy as np\n"
        "from spikectl.contexts import ContextSet\n"
        "from spikectl.envs.env import NeuronControlEnv\n"
        "from spikectl.training.loaders import load_controller\n"
        "cs = ContextSet.load('ctx.npz'); env = NeuronControlEnv(contexts=cs)\n"
        "obs, info = env.reset(seed=0, options={'context': 0})\n"
        f"c = load_controller({who!r}, env=env)\n"
        f"{change}\n"
        "c.act(obs, info)\n"
    )
    return Probe(name, 11, "", code)


def policy_bomb(member: str) -> str:
    return (
        "python - <<'EOF'\n"
        "import io, zipfile, numpy as np\n"
        "h = io.BytesIO(); np.lib.format.write_array_header_1_0(h, {'descr': '<f8', "
        "'fortran_order': False, 'shape': (5 * 2**27,)})\n"
        "with zipfile.ZipFile('bomb.npz', 'w', zipfile.ZIP_DEFLATED) as z:\n"
        "    m = np.array('{}'); b = io.BytesIO(); np.save(b, m); z.writestr('metadata.npy', "
        "b.getvalue())\n"
        f"    with z.open('{member}.npy', 'w', force_zip64=True) as f:\n"
        "        f.write(h.getvalue())\n"
        "        for _ in range(5 * 2**27 * 8 // 2**20): f.write(bytes(2**20))\n"
        "EOF"
    )


PROBES = [
    # 1. not a regular file where a file is read
    Probe("evaluate, checkpoint.pt a FIFO", 1, CKPT_FIFO, ["evaluate", "RUN"]),
    Probe("evaluate, checkpoint.pt -> /dev/zero", 1, CKPT_ZERO, ["evaluate", "RUN"]),
    Probe("evaluate, checkpoint.pt a folder", 1, CKPT_DIR, ["evaluate", "RUN"]),
    Probe("train --resume, checkpoint.pt a FIFO", 1, CKPT_FIFO, ["train", "--resume", "RUN"]),
    Probe("train --resume, checkpoint.pt -> /dev/zero", 1, CKPT_ZERO,
          ["train", "--resume", "RUN"]),  # fmt: skip
    Probe("realtime RUN, checkpoint.pt a FIFO", 1, CKPT_FIFO, ["realtime", "RUN"]),
    Probe("realtime RUN --compiled, checkpoint.pt -> /dev/zero", 1, CKPT_ZERO,
          ["realtime", "RUN", "--compiled"]),  # fmt: skip
    Probe("benchmark RUN, checkpoint.pt a FIFO", 1, CKPT_FIFO,
          ["benchmark", "RUN", "--task", "paper"]),  # fmt: skip
    Probe("evaluate, best_model.pt a FIFO, --model best", 1,
          "rm RUN/best_model.pt && mkfifo RUN/best_model.pt", ["evaluate", "RUN", "--model",
                                                                "best"]),  # fmt: skip
    Probe("realtime, a FIFO as the policy file", 1, "mkfifo p.npz", ["realtime", "p.npz"]),
    Probe("realtime, /dev/zero as the policy file", 1, "ln -s /dev/zero p.npz",
          ["realtime", "p.npz"]),  # fmt: skip
    Probe("realtime --contexts a FIFO", 1, "mkfifo c.npz",
          ["realtime", "do-nothing", "--contexts", "c.npz"]),  # fmt: skip
    Probe("evaluate --contexts /dev/zero", 1, "ln -s /dev/zero c.npz",
          ["evaluate", "RUN", "--contexts", "c.npz"]),  # fmt: skip
    Probe("evaluate, config.json a FIFO", 1, "rm RUN/config.json && mkfifo RUN/config.json",
          ["evaluate", "RUN"]),  # fmt: skip
    Probe("sweep, the sweep file a FIFO", 1, "mkfifo s.json",
          ["sweep", "--config", "s.json", "--sweep-dir", "sw"]),  # fmt: skip
    Probe("torch file API, a FIFO", 1, CKPT_FIFO,
          "from pathlib import Path\nfrom spikectl.training.checkpoint import read_checkpoint\n"
          "read_checkpoint(Path('RUN/checkpoint.pt'))\n"),  # fmt: skip
    # 2. sizes declared inside files, and runaway sizes
    header_probe("policy header n_neurons 1e9 (API)", 2, "n_neurons=10**9"),
    Probe("policy header n_neurons 1e9 (realtime)", 2,
          "python - <<'EOF'\n" + HEADER.replace("CHANGE", "n_neurons=10**9") + "EOF",
          ["realtime", "bad.npz"]),  # fmt: skip
    header_probe("policy header episode_length 1e9", 2, "episode_length=10**9"),
    header_probe("policy header lstm_hidden 1e6", 2, "lstm_hidden=10**6"),
    header_probe("policy header attn_layers 1e5", 2, "attn_layers=10**5"),
    Probe("context file, 5 MB claiming 5 GiB", 2, policy_bomb("weights"),
          "from spikectl.contexts import ContextSet\nContextSet.load('bomb.npz')\n"),  # fmt: skip
    Probe("evaluate --contexts a zip bomb", 2, policy_bomb("weights"),
          ["evaluate", "RUN", "--contexts", "bomb.npz"]),  # fmt: skip
    Probe("policy file, 5 MB claiming 5 GiB", 2, policy_bomb("lstm.lstm.weight_ih_l0"),
          POLICY + "CompiledPolicy.load('bomb.npz')\n"),  # fmt: skip
    Probe("simulate 1e9 steps", 2, "",
          "import numpy as np\nfrom spikectl import simulate\n"
          "simulate(np.zeros((4, 4)), np.broadcast_to(np.int64(-1), (10**9,)))\n"),  # fmt: skip
    Probe("make_vec num_envs 1e9", 2, "",
          "import gymnasium as gym, spikectl\n"
          "gym.make_vec('spikectl/NeuronControl-v0', num_envs=10**9)\n"),  # fmt: skip
    Probe("NeuronControlVectorEnv num_envs 1e12", 2, "",
          "from spikectl.envs.vector_env import NeuronControlVectorEnv\n"
          "NeuronControlVectorEnv(num_envs=10**12)\n"),  # fmt: skip
    # 4. readers missed before
    Probe("metrics.csv with a renamed column", 4,
          "sed -i '1s/test_return/test_retrun/' RUN/metrics.csv",
          "from spikectl.experiments.report import load_runs\nload_runs(['RUN'])\n"),  # fmt: skip
    Probe("policy header nested 100 000 deep", 4,
        "python -c \"import numpy as np; np.savez('deep.npz', metadata=np.array('[' * 100000 "
        "+ ']' * 100000))\"", ["realtime", "deep.npz"]),  # fmt: skip
    # 5. interrupts and the machine (the Ctrl-C probe is in tests/test_output_paths.py)
    Probe("NUMBA_NUM_THREADS=0", 5, "", ["demo"], env={"NUMBA_NUM_THREADS": "0"}),
    Probe("NUMBA_NUM_THREADS=four", 5, "", ["demo"], env={"NUMBA_NUM_THREADS": "four"}),
    Probe("NUMBA_NUM_THREADS=100000", 5, "", ["demo"], env={"NUMBA_NUM_THREADS": "100000"}),
    Probe("NUMBA_OPT=fast", 5, "", ["demo"], env={"NUMBA_OPT": "fast"}),
    Probe("NUMBA_THREADING_LAYER=bogus, import spikectl", 5, "", "import spikectl\n",
          env={"NUMBA_THREADING_LAYER": "bogus"}),  # fmt: skip
    # 6. the controller API
    controller_probe("act(None, info), random", "random", "obs = None"),
    controller_probe("act(obs, None), compiled-free witness", "witness", "info = None"),
    Probe("RandomLegal(seed=-1)", 6, "",
          "from spikectl.envs.controller import RandomLegal\nRandomLegal(seed=-1)\n"),
    Probe("Witness built on another set", 6, "",
          "from spikectl.contexts import make_splits\n"
          "from spikectl.envs.env import NeuronControlEnv\n"
          "from spikectl.envs.controller import Witness\n"
          "a, b = make_splits(4, 4, 5, 20, seed=1)\n"
          "env = NeuronControlEnv(contexts=b); obs, info = env.reset(seed=0, options="
          "{'context': 1})\nWitness(a).act(obs, info)\n"),  # fmt: skip
    # 7. outputs that overwrite anything
    *[Probe(f"benchmark --{flag} RUN/{name}", 7, "",
            ["benchmark", "do-nothing", "--task", "paper", f"--{flag}", f"RUN/{name}"],
            keep=RUN_FILES)  # fmt: skip
      for flag in ("out", "per-network") for name in ("checkpoint.pt", "config.json",
                                                      "metrics.csv")],
    Probe("realtime --out RUN/config.json", 7, "",
          ["realtime", "do-nothing", "--episodes", "1", "--out", "RUN/config.json"],
          keep=RUN_FILES),  # fmt: skip
    Probe("benchmark --out and --per-network one file", 7, "",
          ["benchmark", "do-nothing", "--task", "paper", "--out", "o.csv", "--per-network",
           "./o.csv"]),  # fmt: skip
    Probe("benchmark --out a FIFO", 7, "mkfifo o.csv",
          ["benchmark", "do-nothing", "--task", "paper", "--out", "o.csv"]),  # fmt: skip
    Probe("realtime --out /dev/null", 7, "",
          ["realtime", "do-nothing", "--episodes", "1", "--out", "/dev/null"]),  # fmt: skip
    Probe("realtime --out a symlink", 7, "echo kept > t.csv && ln -s t.csv l.csv",
          ["realtime", "do-nothing", "--episodes", "1", "--out", "l.csv"],
          keep=("t.csv",)),  # fmt: skip
    # 8. results on a closed pipe
    Probe("benchmark --out o.csv | head -1", 8, "",
          ["benchmark", "do-nothing", "--task", "paper", "n16", "--out", "o.csv"],
          expect=RUN, makes=("o.csv",), pipe_head=True),  # fmt: skip
    Probe("realtime --out d.csv | head -1", 8, "",
          ["realtime", "do-nothing", "--episodes", "2", "--out", "d.csv"],
          expect=RUN, makes=("d.csv",), pipe_head=True),  # fmt: skip
    # 9. options that lie or are ignored
    Probe("train --task beside --resume", 9, "", ["train", "--resume", "RUN", "--task", "paper"],
          keep=RUN_FILES),  # fmt: skip
    Probe("realtime pol.npz --model best", 9, "", ["realtime", "pol.npz", "--model", "best"]),
    Probe("benchmark pol.npz --model best", 9, "",
          ["benchmark", "pol.npz", "--task", "paper", "--model", "best"]),  # fmt: skip
    Probe("realtime --rate-hz inf", 9, "", ["realtime", "do-nothing", "--rate-hz", "inf"]),
    Probe("realtime --rate-hz nan", 9, "", ["realtime", "do-nothing", "--rate-hz", "nan"]),
    Probe("benchmark --torch-threads 1000", 9, "",
          ["benchmark", "random", "--task", "paper", "--torch-threads", "1000"]),  # fmt: skip
    Probe("realtime --torch-threads 1000", 9, "",
          ["realtime", "do-nothing", "--torch-threads", "1000"]),  # fmt: skip
    Probe("benchmark --random-seeds 1e8", 9, "",
          ["benchmark", "random", "--task", "paper", "--random-seeds", "100000000"]),
    Probe("train smoke --task paper: the task's 60-step sets", 9, "",
          "from spikectl.cli.training import parse_train\n"
          "c = parse_train(['smoke', '--task', 'paper'])\n"
          "assert c.config.env.episode_length == 60, c.config.env.episode_length\n"
          "print('REFUSED-OR-RIGHT')\n", expect=RUN),  # fmt: skip
    # 10. policy files
    header_probe("policy v_threshold_mV 1e308", 10, "v_threshold_mV=1e308"),
    header_probe("policy v_threshold_mV below v_rest", 10, "v_threshold_mV=-90.0"),
    header_probe("policy do_nothing_head changed", 10, "do_nothing_head='pooled'"),
    header_probe("policy layer_norm_eps 1e9", 10, "layer_norm_eps=1e9"),
    header_probe("policy version 1 (no checksum)", 10, "format_version=1"),
    # 11. nonsense in observations
    *[controller_probe(f"{change_name}, {who}", who, change)
      for who in ("RUN", "pol.npz") for change_name, change in (
          ("NaN voltages", "obs = {**obs, 'voltage': obs['voltage'] * np.nan}"),
          ("pattern 7.5", "obs = {**obs, 'pattern': obs['pattern'] * 7.5}"),
          ("mask allowing nothing", "info = {**info, 'action_mask': info['action_mask'] & False}"),
          ("act(None, info)", "obs = None"),
      )],  # fmt: skip
    # 12. witnesses
    Probe("a wrong witness, checksum recomputed", 12, "",
          "import numpy as np\nfrom spikectl.contexts import ContextSet\n"
          "from spikectl.contexts.context import Context\n"
          "cs = ContextSet.load('ctx.npz')\n"
          "bad = ContextSet([Context(c.weights, c.target, c.pattern, np.full_like(c.witness, -1))"
          " for c in cs], cs.params, cs.seed)\nbad.save('bad.npz')\n"
          "ContextSet.load('bad.npz')\n"),  # fmt: skip
    # 13. file names read as flags
    Probe("evaluate --contexts test_contexts.npz of another length", 13,
          "python -c \"from spikectl.contexts import make_splits; "
          "make_splits(3, 3, 5, 60, seed=4)[1].save('test_contexts.npz')\"",
          ["evaluate", "RUN", "--contexts", "test_contexts.npz"]),  # fmt: skip
    # 14. the machine record
    Probe("a damaged machine.json on resume", 14, "echo '{bad' > RUN/machine.json",
          "import warnings\nfrom pathlib import Path\n"
          "from spikectl.training.machine import record_machine\n"
          "with warnings.catch_warnings(record=True) as caught:\n"
          "    warnings.simplefilter('always')\n    record_machine(Path('RUN'), 8)\n"
          "assert any('damaged' in str(w.message) for w in caught), 'silently replaced'\n"
          "print([str(w.message) for w in caught])\n", expect=RUN),  # fmt: skip
]


API_WRAPPER = """
import sys
try:
    exec(compile(CODE, "probe", "exec"))
except Exception as error:
    if not isinstance(error, (ValueError, OSError)) and not type(error).__module__.startswith(
        "spikectl"
    ):
        raise
    print("REFUSED", type(error).__name__ + ":", " ".join(str(error).split()))
    sys.exit(2)
"""
"""API probes: a ValueError (every validation error is one), an OSError about a file or
one of spikectl's named errors (RunDirError) is the API's refusal; anything else
propagates as a traceback."""


def digest(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    except OSError:
        return None


def prepare(base: Path, python: str) -> None:
    shutil.copytree(SMOKE_RUN, base / "RUN")
    subprocess.run([python, "-c",
                    "from spikectl.agents import export_policy, make_agent\n"
                    "from spikectl.contexts import make_splits\n"
                    "export_policy(make_agent('tdrqn', 5, 20), 'pol.npz')\n"
                    "make_splits(3, 3, 5, 20, seed=4)[1].save('ctx.npz')\n"],
                   cwd=base, check=True)  # fmt: skip


def classify(probe: Probe, folder: Path, python: str) -> tuple[str, str]:
    if probe.setup:  # its ``python`` is the interpreter probed (bin/python in the root)
        path = f"{folder.parent / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}"
        subprocess.run(probe.setup, shell=True, cwd=folder, check=True, executable="/bin/bash",
                       env={**os.environ, "PATH": path})  # fmt: skip
    before = {name: digest(folder / name) for name in probe.keep}
    if isinstance(probe.command, str):
        argv = [python, "-c", API_WRAPPER.replace("CODE", repr(probe.command))]
    else:  # as the ``spikectl`` command runs (its entry point, outside the package)
        argv = [python, "-m", "_spikectl_launcher", *probe.command]
    environment = {**os.environ, **probe.env}
    process = subprocess.Popen(argv, cwd=folder, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=environment)  # fmt: skip
    try:
        if probe.pipe_head:
            process.stdout.readline()
            process.stdout.close()
            err = process.stderr.read()
            process.wait(TIMEOUT_S)
            out = ""
        else:
            out, err = process.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        return "hang", f"no end within {TIMEOUT_S} s"
    lines = [line for line in err.strip().splitlines() if line]
    last = lines[-1] if lines else ""
    if any(digest(folder / name) != before[name] for name in probe.keep):
        return "lost", "a file that must survive changed: " + last
    if any(not (folder / name).is_file() for name in probe.makes):
        return "lost", f"{probe.makes} not written (exit {process.returncode})"
    if "Traceback" in err:
        if isinstance(probe.command, str) and last.startswith("AssertionError"):
            return "silent", last  # the probe's own check of the result failed
        return "traceback", last
    if probe.expect == REFUSE:
        if isinstance(probe.command, str):
            if process.returncode == 2 and out.startswith("REFUSED"):
                return "ok", out.strip().splitlines()[0]
            return "silent", f"the API accepted it: {out.strip()[-120:]}"
        if process.returncode == 2 and len(lines) == 1 and lines[0].startswith("spikectl: error"):
            return "ok", last
        return "silent", f"exit {process.returncode}: {last or out.strip()[-120:]}"
    if process.returncode not in (0, 141):
        return "silent", f"exit {process.returncode}: {last}"
    return "ok", last or out.strip().splitlines()[-1:]


def run_probes(probes, judge=None, prefix: str = "hostile4-") -> None:
    """Parse ``--python`` and ``--only``, run each probe in a fresh copy of the prepared
    folder, print one line per probe and the counts; exit 1 unless every one is ``ok``.
    ``judge(probe, folder, python)`` classifies (``classify`` by default); the later
    rounds' scripts call this with their own probes and judges."""
    judge = judge or classify
    parser = argparse.ArgumentParser(description=(sys.modules["__main__"].__doc__ or "")
                                     .splitlines()[0])  # fmt: skip
    parser.add_argument("--python", default=sys.executable)
    parser.add_argument("--only", default="", help="comma-separated words of probe names")
    args = parser.parse_args()
    counts: dict[str, int] = {}
    with tempfile.TemporaryDirectory(prefix=prefix) as root:
        base = Path(root) / "base"
        base.mkdir()
        (Path(root) / "bin").mkdir()  # a script, not a link: a venv's python finds its
        shim = Path(root) / "bin" / "python"  # pyvenv.cfg by the path it was started as
        shim.write_text(f'#!/bin/sh\nexec "{args.python}" "$@"\n')
        shim.chmod(0o755)
        prepare(base, args.python)
        for index, probe in enumerate(probes):
            if args.only and not any(word in probe.name for word in args.only.split(",")):
                continue
            folder = Path(root) / f"probe{index}"
            shutil.copytree(base, folder, symlinks=True)
            start = time.monotonic()
            outcome, detail = judge(probe, folder, args.python)
            counts[outcome] = counts.get(outcome, 0) + 1
            seconds = time.monotonic() - start
            print(f"{outcome:10} class {probe.klass!s:2} {probe.name} ({seconds:.0f} s): "
                  f"{str(detail)[:220]}", flush=True)  # fmt: skip
            shutil.rmtree(folder, ignore_errors=True)
    print("counts:", ", ".join(f"{key} {value}" for key, value in sorted(counts.items())))
    sys.exit(0 if set(counts) <= {"ok"} else 1)


def main() -> None:
    run_probes(PROBES)


if __name__ == "__main__":
    main()
