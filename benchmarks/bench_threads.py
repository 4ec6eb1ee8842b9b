"""Training speed with a busy neighbour: Torch thread settings on a shared machine.

Times a short training job (the quick preset's networks and update ratio, a fixed
number of environment steps, no evaluation beyond the first) as a whole process with
1 and with 2 Torch threads, alone and beside one busy-loop process (a neighbour that
wants a whole core), interleaved. Reports the median wall time of each and the
slowdown the neighbour causes: with a fair share the slowdown of a job that uses the
whole machine is at most 2x (it keeps one of the two cores), and a 1-thread job should
barely notice the neighbour.

    python benchmarks/bench_threads.py [--steps 24000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

BUSY_LOOP = "while True:\n    pass\n"


def run_job(threads: int, steps: int) -> float:
    """Wall seconds of one training job in a fresh process."""
    with tempfile.TemporaryDirectory() as run_dir:
        command = [
            sys.executable, "-m", "spikectl.cli", "train", "quick",
            "--total-env-steps", str(steps), "--torch-threads", str(threads),
            "--eval-every-episodes", str(10**6), "--checkpoint-every-episodes", str(10**6),
            "--n-val", "0", "--no-progress", "--run-dir", f"{run_dir}/run",
        ]  # fmt: skip
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=24_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{os.cpu_count()} CPU cores; quick preset, {args.steps:,} environment steps per job")
    times: dict[tuple[int, bool], list[float]] = {}
    for _ in range(args.repeats):
        for threads in (1, 2):
            for busy in (False, True):
                neighbour = subprocess.Popen([sys.executable, "-c", BUSY_LOOP]) if busy else None
                try:
                    seconds = run_job(threads, args.steps)
                finally:
                    if neighbour is not None:
                        neighbour.kill()
                        neighbour.wait()
                times.setdefault((threads, busy), []).append(seconds)
    print("| Torch threads | alone (s) | beside a busy loop (s) | slowdown |")
    print("|---:|---:|---:|---:|")
    for threads in (1, 2):
        alone = float(np.median(times[(threads, False)]))
        busy = float(np.median(times[(threads, True)]))
        print(f"| {threads} | {alone:.1f} | {busy:.1f} | {busy / alone:.2f}x |")


if __name__ == "__main__":
    main()
