"""Every controller through the 1 kHz real-time rig, at n = 8 and n = 32 (issue 24;
the table of docs/realtime.md).

Each controller comes from ``spikectl.load_controller`` (the same call as
``spikectl realtime``) and plays one episode on each of the first ``--episodes``
contexts of the generated test set (make_splits(100, 100, n, seed=0, n_val=100)),
after one untimed warm-up episode, through ``run_realtime`` at 1 kHz: a decision later
than 1 ms is a deadline miss and its frame does nothing. The process is pinned to one
core (``--cpu``), one Torch thread. The controllers: do nothing, random, the witness,
identify-and-plan, the oracle planner (it plans the whole episode in its first
decision), and a trained TDRQN (``--run``, a run directory of the quick preset) as the
PyTorch network and as its compiled policy. A network trained at n = 8 plays n = 32 as
it is (per-neuron networks run on any n): its latency is what the table is for there.
The slow controllers at n = 32 (identify-and-plan, the oracle) play
``--slow-episodes`` episodes.

    python benchmarks/bench_realtime_controllers.py --run RUN_DIR [--n 8 32]
        [--episodes 100] [--slow-episodes 20] [--cpu 1]
"""

from __future__ import annotations

import argparse
import os
import sys

from spikectl.cli.baseline_policies import generated_split
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.realtime import run_realtime
from spikectl.neuron.extensions import Extensions
from spikectl.training.loaders import load_controller
from spikectl.training.machine import cpu_description

SLOW_AT_32 = ("identify-and-plan", "oracle")


def controllers(run: str | None) -> list[tuple[str, str, dict]]:
    """(label, source, load_controller keywords) of every controller to time."""
    named = [(name, name, {}) for name in ("do-nothing", "random", "witness",
                                           "identify-and-plan", "oracle")]  # fmt: skip
    if run is None:
        return named
    return named + [
        ("TDRQN, PyTorch", run, {"model": "best"}),
        ("TDRQN, compiled", run, {"model": "best", "compiled": True}),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", default=None, help="a trained quick-preset run directory")
    parser.add_argument("--n", type=int, nargs="+", default=[8, 32])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--slow-episodes", type=int, default=20)
    parser.add_argument("--cpu", type=int, default=None)
    parser.add_argument("--only", nargs="+", default=None, help="labels to time")
    args = parser.parse_args()
    if args.cpu is not None:
        os.sched_setaffinity(0, {args.cpu})
    print(f"{cpu_description()['cpu']}; load average {os.getloadavg()[0]:.2f} at the start; "
          f"cores {sorted(os.sched_getaffinity(0))}")  # fmt: skip
    print()
    print("| n | controller | episodes | median (ms) | p99 (ms) | max (ms) | deadline misses "
          "| mean return |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for n in args.n:
        contexts = generated_split("test", n, Extensions())
        env = NeuronControlEnv(contexts=contexts)
        for label, source, keywords in controllers(args.run):
            if args.only and label not in args.only:
                continue
            controller = load_controller(source, env=env, **keywords)
            if "torch" in sys.modules:  # a PyTorch controller: one thread, like the rig
                sys.modules["torch"].set_num_threads(1)
            episodes = args.slow_episodes if n >= 32 and label in SLOW_AT_32 else args.episodes
            run_realtime(env, controller, [0])  # warm-up (compiles, caches)
            report = run_realtime(env, controller, range(episodes))
            s = report.summary()
            print(f"| {n} | {label} | {episodes} | {s['median_ms']:.3f} | {s['p99_ms']:.3f} | "
                  f"{s['max_ms']:.3f} | {s['misses']} of {report.missed.size} | "
                  f"{s['mean_return']:.3f} |", flush=True)  # fmt: skip
    print()
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
