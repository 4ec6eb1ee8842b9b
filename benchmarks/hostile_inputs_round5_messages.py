"""The hostile-input probes of round 5's class "messages that mislead" (issue 58), kept so
they can be rerun.

Built on round 4's machinery (``benchmarks/hostile_inputs_round4.py``: the fresh folder
with a copy of a small finished run ``RUN``, a compiled policy ``pol.npz`` and a context
set ``ctx.npz``; the same outcomes), with three more outcomes:

- ``misleading``: refused in one line, but the line does not name what it must (the
  kind of file found, the setting that differs and both its values, the array that is
  wrong);
- ``half-made``: refused, but something the command made is left behind (a run
  directory, one file of a pair);
- ``silent`` also covers a probe's own check failing (an API probe's AssertionError):
  SIGTERM that ends without a word, a progress line showing an old evaluation.

Run: ``python benchmarks/hostile_inputs_round5_messages.py [--python PYTHON] [--only WORD]``
(PYTHON: the interpreter of the spikectl to probe; default this one). Prints one line per
probe and the counts; exits 1 if any probe is not ``ok``.
"""

from __future__ import annotations

import functools
import subprocess
import sys
import types
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import hostile_inputs_round4 as round4  # noqa: E402
from hostile_inputs_round4 import REFUSE, RUN, Probe, classify, run_probes  # noqa: E402

# A probe's output may hold a name that is not UTF-8 (the run directory it was given):
# round 4's reader decodes it with escapes instead of failing.
round4.subprocess = types.SimpleNamespace(
    **{**vars(subprocess), "Popen": functools.partial(subprocess.Popen, errors="backslashreplace")}
)


@dataclass(frozen=True)
class MessageProbe(Probe):
    words: tuple[str, ...] = ()
    """What the refusal must say: each entry is one or more alternatives split by ``|``
    (case-insensitive)."""
    absent: tuple[str, ...] = ()
    """Paths (relative to the folder) that must not exist afterwards."""


SMOKE = ["train", "smoke", "--run-dir", "new"]
SMALL_CONTEXTS = ["contexts", "--out-dir", "out", "--n-train", "3", "--n-test", "3",
                  "--n-neurons", "5", "--episode-length", "20"]  # fmt: skip
WHAT_INIT_FROM_TAKES = "run directory"


def init_from_probe(what: str, source: str, words: tuple[str, ...], *flags: str,
                    setup: str = "") -> MessageProbe:  # fmt: skip
    """``train smoke --init-from SOURCE [FLAGS]``: refused in one line saying ``words``,
    with no run directory left behind."""
    command = [*SMOKE, "--init-from", source, *flags]
    return MessageProbe(f"train --init-from {what}", 1, setup, command, words=words,
                        absent=("new",))  # fmt: skip


SHORT_ARRAY = (
    "python - <<'EOF'\n"
    "import numpy as np\n"
    "d = np.load('ctx.npz'); a = {k: d[k] for k in d.files}\n"
    "CHANGE\n"
    "np.savez('bad.npz', **a)\n"
    "EOF"
)
LOAD_BAD = "from spikectl.contexts import ContextSet\nContextSet.load('bad.npz')\n"


def bad_array_probe(what: str, change: str, words: tuple[str, ...],
                    command: str | list[str] = LOAD_BAD) -> MessageProbe:  # fmt: skip
    """A context set whose arrays ``change`` breaks (``a`` is the dict of arrays), read by
    ``command`` (the API's load by default): refused in one line saying ``words``."""
    return MessageProbe(f"context set with {what}", 3, SHORT_ARRAY.replace("CHANGE", change),
                        command, words=words)  # fmt: skip
REHEADED_POLICY = (
    "import json, numpy as np\n"
    "from spikectl.agents.compiled import CompiledPolicy\n"
    "from spikectl.agents.policy_file import policy_checksum\n"
    "from spikectl.agents.policy_header import parse_header\n"
    "d = np.load('pol.npz'); a = {k: d[k] for k in d.files}\n"
    "h = json.loads(str(a['metadata'])); h.update(CHANGE)\n"
    "weights = {k: v for k, v in a.items() if k != 'metadata'}\n"
    "h['checksum'] = policy_checksum(parse_header('x', np.array(json.dumps(h))), weights)\n"
    "a['metadata'] = np.array(json.dumps(h)); np.savez('bad.npz', **a)\n"
    "try:\n"
    "    CompiledPolicy.load('bad.npz')\n"
    "except ValueError as error:\n"
    "    assert len(str(error)) < 400, f'{len(str(error))} characters: {str(error)[:200]}'\n"
    "    raise\n"
)


def _reheaded(what: str, change: str, words: tuple[str, ...]) -> MessageProbe:
    """A compiled policy whose header says ``change`` over unchanged weights (its checksum
    recomputed, so only the cross-check against the weights can catch it)."""
    return MessageProbe(what, 6, "", REHEADED_POLICY.replace("CHANGE", change), words=words)


SIGTERM_DURING_TRAIN = """
import os, signal, subprocess, sys, time
from pathlib import Path
process = subprocess.Popen(
    [sys.executable, '-m', '_spikectl_launcher', 'train', 'smoke', '--run-dir', 'new',
     '--total-env-steps', '64000', '--checkpoint-every-episodes', '100000'],
    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
deadline = time.monotonic() + 120
while not Path('new/metrics.csv').exists() and time.monotonic() < deadline:
    time.sleep(0.2)
time.sleep(3)
process.send_signal(signal.SIGTERM)
out, err = process.communicate(timeout=120)
lines = [line for line in err.splitlines() if line.strip()]
assert process.returncode == 143, f'exit {process.returncode}, stderr {err[-200:]!r}'
assert len(lines) == 1 and 'resume' in lines[0], f'stderr {err[-300:]!r}'
assert Path('new/checkpoint.pt').is_file(), 'no checkpoint written at SIGTERM'
print(lines[0])
"""
PROGRESS_LINE = """
import csv, subprocess, sys
done = subprocess.run(
    [sys.executable, '-m', '_spikectl_launcher', 'train', 'smoke', '--run-dir', 'new',
     '--progress', '--eval-every-episodes', '96'],
    capture_output=True, text=True, timeout=170)
assert done.returncode == 0, done.stderr[-300:]
rows = list(csv.DictReader(open('new/metrics.csv')))
last = f"{float(rows[-1]['test_return']):.3f}"
bar = done.stderr.replace('\\r', '\\n').strip().splitlines()[-1]
assert f'test={last}' in bar, f'the last progress line {bar!r} lacks the last test {last}'
wrote = [line for line in done.stdout.splitlines() if line.startswith('wrote')][-1]
assert 'best_model.pt' in wrote, f'{wrote!r} omits best_model.pt'
print(bar[-80:], '|', wrote)
"""

PROBES = [
    # --init-from: every kind of file named, and the setting that differs with both values
    init_from_probe(
        "a run of another episode length",
        "RUN",
        ("episode length|episode_length", "20", "30"),
        "--episode-length",
        "30",
    ),  # fmt: skip
    init_from_probe("a run of another architecture", "RUN", ("tdrqn", "ddrqn"), "--arch", "ddrqn"),
    init_from_probe("a compiled policy", "pol.npz", ("compiled policy", WHAT_INIT_FROM_TAKES)),
    init_from_probe("a context set", "ctx.npz", ("context set", WHAT_INIT_FROM_TAKES)),
    init_from_probe("a checkpoint.pt", "RUN/checkpoint.pt", ("checkpoint", WHAT_INIT_FROM_TAKES)),
    init_from_probe(
        "a text file",
        "notes.txt",
        ("notes.txt", WHAT_INIT_FROM_TAKES),
        setup="echo hello > notes.txt",
    ),  # fmt: skip
    MessageProbe(
        "realtime on a context set",
        1,
        "",
        ["realtime", "ctx.npz"],
        words=("context set", "compiled policy"),
    ),  # fmt: skip
    MessageProbe(
        "realtime on a best_model.pt",
        1,
        "",
        ["realtime", "RUN/best_model.pt"],
        words=("model", "run directory"),
    ),  # fmt: skip
    MessageProbe(
        "evaluate --contexts a compiled policy",
        1,
        "",
        ["evaluate", "RUN", "--contexts", "pol.npz"],
        words=("compiled policy", "context set"),
    ),  # fmt: skip
    MessageProbe(
        "load_controller on a checkpoint.pt",
        1,
        "",
        "import spikectl\nspikectl.load_controller('RUN/checkpoint.pt')\n",
        words=("checkpoint", "run directory"),
    ),  # fmt: skip
    # run paths checked before anything is made
    MessageProbe(
        "train --run-dir a non-UTF-8 name",
        2,
        "",
        ["train", "smoke", "--run-dir", "r\udcff"],
        words=("UTF-8",),
        absent=("r\udcff",),
    ),  # fmt: skip
    MessageProbe(
        "train --run-dir under a file",
        2,
        "",
        ["train", "smoke", "--run-dir", "pol.npz/run"],
        words=("pol.npz",),
    ),
    # context-set arrays, each checked and named
    bad_array_probe("a short targets array (API)", "a['targets'] = a['targets'][:2]",
                    ("targets", "(3,)")),  # fmt: skip
    bad_array_probe("a short targets array (evaluate)", "a['targets'] = a['targets'][:2]",
                    ("targets",), ["evaluate", "RUN", "--contexts", "bad.npz"]),  # fmt: skip
    bad_array_probe("float patterns", "a['patterns'] = a['patterns'] * 0.5",
                    ("patterns", "bool")),  # fmt: skip
    bad_array_probe("witnesses of another length", "a['witnesses'] = a['witnesses'][:, :5]",
                    ("witnesses", "(3, 20)")),  # fmt: skip
    bad_array_probe("1-D weights", "a['weights'] = a['weights'].reshape(-1)",
                    ("weights", "(3, 5, 5)")),  # fmt: skip
    # the pair of sets of spikectl contexts
    MessageProbe(
        "contexts --out-dir with a dangling link as the test set",
        4,
        "mkdir out && ln -s ../nowhere/t.npz out/test_contexts.npz",
        SMALL_CONTEXTS,
        words=("test_contexts.npz",),
        absent=("out/train_contexts.npz",),
    ),  # fmt: skip
    MessageProbe(
        "contexts --overwrite with a link as the test set",
        4,
        "echo kept > kept.npz && mkdir out && ln -s ../kept.npz out/test_contexts.npz",
        [*SMALL_CONTEXTS, "--overwrite"],
        keep=("kept.npz",),
        words=("test_contexts.npz", "link"),
        absent=("out/train_contexts.npz",),
    ),  # fmt: skip
    # SIGTERM, what Slurm and Docker send
    MessageProbe("SIGTERM during train", 5, "", SIGTERM_DURING_TRAIN, expect=RUN),
    # compiled-policy headers cross-checked against their weights (checksum recomputed)
    _reheaded(
        "policy header lstm_hidden 64 over 128-wide weights",
        "lstm_hidden=64",
        ("lstm_hidden", "64", "128"),
    ),
    _reheaded(
        "policy header attn_layers 1 over 2 layers", "attn_layers=1", ("attn_layers", "1", "2")
    ),
    _reheaded(
        "policy header architecture ddrqn over a TDRQN",
        "architecture='ddrqn'",
        ("architecture", "tdrqn", "ddrqn"),
    ),
    _reheaded(
        "policy header head_hidden [256] over [256, 128]", "head_hidden=[256]", ("head_hidden",)
    ),
    # what a training run shows and says it wrote
    MessageProbe(
        "train --progress: the latest evaluation, every file written",
        7,
        "",
        PROGRESS_LINE,
        expect=RUN,
    ),  # fmt: skip
]


def judge(probe: MessageProbe, folder: Path, python: str) -> tuple[str, str]:
    outcome, detail = classify(probe, folder, python)
    left = [name for name in probe.absent if (folder / name).exists()]
    if left:
        return "half-made", f"{', '.join(left)} left behind: {detail}"
    if outcome == "ok" and probe.expect == REFUSE:
        text = str(detail).lower()
        missing = [w for w in probe.words if not any(a.lower() in text for a in w.split("|"))]
        if missing:
            return "misleading", f"names no {missing}: {detail}"
    return outcome, detail


def main() -> None:
    run_probes(PROBES, judge, prefix="hostile5m-")


if __name__ == "__main__":
    main()
