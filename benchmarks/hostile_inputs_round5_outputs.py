"""The hostile-input probes of round 5 (issue 58) on outputs, seeds and actions, rerunnable.

Three classes, each probed where it enters: (1) outputs that replace a user's file
(``benchmark``/``realtime --out``, ``baselines`` and ``demo`` over an earlier run's files,
two writers of one file at once); (2) seeds given to ``reset`` of the single, batched and
flat environments; (3) the message of one bad action among many environments (the Stable-Baselines3
adapter's is tested in tests/test_vector_env.py, where SB3 is installed). The probe
machinery (folders, the run to copy, classification) is round 4's
(``hostile_inputs_round4.py``): ``ok``, ``traceback``, ``silent``, ``hang`` or ``lost``.

Run: ``python benchmarks/hostile_inputs_round5_outputs.py [--python PYTHON] [--only WORD]``.
Prints one line per probe and the counts; exits 1 if any probe is not ``ok``.
"""

from __future__ import annotations

from hostile_inputs_round4 import REFUSE, RUN, Probe, classify, run_probes

BENCHMARK = ["benchmark", "do-nothing", "--task", "paper"]
REALTIME = ["realtime", "do-nothing", "--episodes", "1"]
KEPT = "echo 'a file of the user' > "

CONCURRENT = """
import subprocess, sys
command = [sys.executable, '-m', '_spikectl_launcher', *ARGS]
runs = [subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for _ in range(2)]
codes = sorted(run.wait() for run in runs)
lines = [run.stderr.read().strip() for run in runs]
assert codes == [0, 2], f'two writers of one file both ran (exit {codes}): one result lost'
print('the second was refused:', [line for line in lines if line][0][:200])
"""


def concurrent(name: str, args: list[str]) -> Probe:
    return Probe(name, 1, "", CONCURRENT.replace("ARGS", repr(args)), expect=RUN)


SEED_CHECK = """
import gymnasium as gym, numpy as np, spikectl
env = MAKE
try:
    env.reset(seed=SEED)
except Exception as error:
    message = str(error)
    assert 'seed' in message and WANT in message, f'{type(error).__name__}: {message[:200]}'
    raise
print('reset ran')
"""


def seed_probe(env_id: str, seed: str, want: str = "", vector: bool = True) -> Probe:
    make = f"gym.make_vec({env_id!r}, 3)" if vector else f"gym.make({env_id!r})"
    code = SEED_CHECK.replace("MAKE", make).replace("SEED", seed).replace("WANT", repr(want))
    kind = "make_vec(3)" if vector else "make"
    return Probe(f"{kind} {env_id} reset(seed={seed})", 2, "", code,
                 expect=RUN if not want else REFUSE)  # fmt: skip


ACTIONS = """
import gymnasium as gym, numpy as np, spikectl
env = MAKE
env.reset(seed=0)
actions = np.full(200_000, FILL, dtype=np.int64)
actions[123_456] = 99
try:
    env.step(actions)
except ValueError as error:
    message = str(error)
    assert len(message) < 400 and all(word in message for word in ('1 of 200', '123456', '99')), (
        f'{len(message):,} characters: {message[:120]}')
    raise
"""


def action_probe(name: str, make: str, fill: int) -> Probe:
    code = ACTIONS.replace("MAKE", make).replace("FILL", str(fill))
    return Probe(f"one bad action among 200 000, {name}", 3, "", code)


PAPER, FLAT = "spikectl/NeuronControl-v0", "spikectl/NeuronControlFlat-v0"
# fmt: off
SEEDS = [("0.5", "0.5"), ("True", "True"), ("'x'", "'x'"), ("-1", "-1"),
         ("[0.5, 1.7, 2.9]", "0.5"), ("{0: 1, 1: 2, 2: 3}", "dict"), ("[1, 2]", "2"),
         ("np.int64(3)", ""), ("[np.int64(1), None, 2]", ""), ("np.arange(3)", "")]

PROBES = [
    # 1. outputs that replace a user's file, and two writers of one file
    Probe("benchmark --out over an existing file", 1, KEPT + "o.csv",
          [*BENCHMARK, "--out", "o.csv"], keep=("o.csv",)),
    Probe("benchmark --per-network over an existing file", 1, KEPT + "p.csv",
          [*BENCHMARK, "--per-network", "p.csv"], keep=("p.csv",)),
    Probe("realtime --out over an existing file", 1, KEPT + "d.csv",
          [*REALTIME, "--out", "d.csv"], keep=("d.csv",)),
    Probe("baselines --contexts OTHER.npz beside the default split's CSV", 1,
          "mkdir -p runs/baselines && " + KEPT + "runs/baselines/baselines.csv",
          ["baselines", "--contexts", "ctx.npz", "--random-seeds", "2", "--oracle-width", "4",
           "--identify-width", "2"], expect=RUN,
          keep=("runs/baselines/baselines.csv",)),
    Probe("demo over an earlier demo's results.json", 1,
          "mkdir -p runs/demo && " + KEPT + "runs/demo/results.json",
          ["demo", "--n-train", "3", "--n-test", "3"], keep=("runs/demo/results.json",)),
    Probe("plot over an earlier plot's figure4.png", 1,
          "mkdir -p sw/trials sw/figures && cp -r RUN sw/trials/t0 && "
          + KEPT + "sw/figures/figure4.png", ["plot", "sw"], keep=("sw/figures/figure4.png",)),
    Probe("baselines run twice on one input", 1,
          "python -m _spikectl_launcher baselines --contexts ctx.npz --random-seeds 2 "
          "--oracle-width 4 --identify-width 2 > /dev/null",
          ["baselines", "--contexts", "ctx.npz", "--random-seeds", "2", "--oracle-width", "4",
           "--identify-width", "2"], keep=("runs/baselines/baselines-ctx.csv",)),
    Probe("benchmark --out over an existing file with --overwrite", 1, KEPT + "o.csv",
          [*BENCHMARK, "--out", "o.csv", "--overwrite"], expect=RUN, makes=("o.csv",)),
    Probe("benchmark --out o.csv beside a stale lock of a dead process", 1,
          "echo 999999 > .o.csv.lock", [*BENCHMARK, "--out", "o.csv"], expect=RUN,
          makes=("o.csv",)),
    concurrent("two benchmarks on one --out at once", [*BENCHMARK, "--out", "o.csv"]),
    concurrent("two realtime on one --out at once", [*REALTIME, "--out", "d.csv"]),
    # 2. seeds given to reset
    *[seed_probe(env_id, seed, want) for env_id in (PAPER, FLAT) for seed, want in SEEDS],
    *[seed_probe(env_id, seed, want, vector=False) for env_id in (PAPER, FLAT)
      for seed, want in (("0.5", "0.5"), ("True", "True"), ("-1", "-1"), ("[1, 2]", "list"),
                         ("np.int64(3)", ""))],
    # 3. the message of one bad action among many environments
    action_probe("make_vec paper id", f"gym.make_vec({PAPER!r}, 200_000)", -1),
    action_probe("make_vec flat id", f"gym.make_vec({FLAT!r}, 200_000)", 0),
]
# fmt: on


def main() -> None:
    run_probes(PROBES, classify, prefix="hostile5-")


if __name__ == "__main__":
    main()
