"""Per-decision latency of identify-and-plan controlling one environment (issue 24, part 4;
docs/benchmarks.md).

``IdentifyAndPlan()`` with its default settings plays one episode on each of the first
``--episodes`` contexts of the generated test split (``make_splits(100, 100, n, seed=0,
n_val=100)``), in one ``NeuronControlEnv`` (``env.reset(seed=i, options={"context":
i})``), and each ``policy.act`` is timed alone (``time.perf_counter_ns``). One untimed
episode (context 0) warms the code up first. Reports, per n, the median, p99 and max per
decision (wall clock), the fraction over 1 ms, the p99 and max of the CPU time the
decision took (``time.thread_time_ns``: what it would take on an idle core, without the
time the process waited for the core) and the mean return.

``--baseline REV`` measures a second implementation in the same run: the ``spikectl``
package of git revision REV (``git archive``, into a temporary folder) beside the working
tree's. Each runs in a worker process of its own (a package cannot be imported twice),
both pinned to the same core, and the two alternate episode by episode (so both see the
same machine); the report adds the ratios baseline / current and whether the two chose
the same actions in every episode.

The benchmark pins itself (and its workers) to one core, ``--core`` (default: the last
one it may use), with one Numba and one BLAS thread.

    python benchmarks/bench_identify_and_plan.py [--episodes 10] [--n 8 32]
        [--baseline REV] [--core C]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


class Player:
    """Plays timed episodes of identify-and-plan with the ``spikectl`` it imports."""

    def __init__(self) -> None:
        self.envs: dict[int, object] = {}

    def episode(self, n: int, index: int) -> dict:
        import spikectl
        from spikectl.planning import IdentifyAndPlan

        if n not in self.envs:
            test = spikectl.make_splits(100, 100, n, seed=0, n_val=100)[1]
            self.envs[n] = spikectl.NeuronControlEnv(contexts=test)
        env = self.envs[n]
        policy = IdentifyAndPlan()
        observation, info = env.reset(seed=index, options={"context": index})
        times, cpu, actions, total, done = [], [], [], 0.0, False
        while not done:
            start, start_cpu = time.perf_counter_ns(), time.thread_time_ns()
            action = policy.act(observation, info)
            times.append(time.perf_counter_ns() - start)
            cpu.append(time.thread_time_ns() - start_cpu)
            actions.append(action)
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            done = terminated or truncated
        return {"times_ns": times, "cpu_ns": cpu, "actions": actions, "return": total}


def worker() -> None:
    """Serve ``{"n": n, "episode": i}`` lines from stdin, one JSON answer per line."""
    player = Player()
    for line in sys.stdin:
        request = json.loads(line)
        print(json.dumps(player.episode(request["n"], request["episode"])), flush=True)


class Worker:
    def __init__(self, pythonpath: str | None) -> None:
        threads = ("NUMBA", "OMP", "OPENBLAS", "MKL")
        env = dict(os.environ, **{f"{name}_NUM_THREADS": "1" for name in threads})
        env.pop("PYTHONPATH", None)
        if pythonpath is not None:
            env["PYTHONPATH"] = pythonpath
        self.process = subprocess.Popen(
            [sys.executable, __file__, "--worker"], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, env=env, cwd=REPO,
        )  # fmt: skip

    def episode(self, n: int, index: int) -> dict:
        self.process.stdin.write(json.dumps({"n": n, "episode": index}) + "\n")
        self.process.stdin.flush()
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError("a worker exited (its error is printed above)")
        return json.loads(line)

    def close(self) -> None:
        try:
            self.process.stdin.close()
        except BrokenPipeError:
            pass
        self.process.wait()


def stats(times_ns: list[int], cpu_ns: list[int], returns: list[float]) -> dict[str, float]:
    times, cpu = np.array(times_ns) * 1e-6, np.array(cpu_ns) * 1e-6  # ms
    return {
        "median": float(np.median(times)),
        "p99": float(np.percentile(times, 99)),
        "max": float(times.max()),
        "over_1ms": float(np.mean(times > 1.0)),
        "cpu_p99": float(np.percentile(cpu, 99)),
        "cpu_max": float(cpu.max()),
        "mean_return": float(np.mean(returns)),
        "decisions": times.size,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--n", type=int, nargs="+", default=[8, 32])
    parser.add_argument("--baseline", metavar="REV", help="git revision to compare with")
    parser.add_argument("--core", type=int, help="the core to run on (default: the last)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker()
        return
    # Imported here: a worker may run another revision's spikectl.
    from spikectl.training.machine import cpu_description

    if hasattr(os, "sched_setaffinity"):
        core = max(os.sched_getaffinity(0)) if args.core is None else args.core
        os.sched_setaffinity(0, {core})  # the workers inherit it
        pinned = f"pinned to core {core}"
    else:
        pinned = "not pinned"
    implementations = {"current": Worker(None)}
    folder = None
    if args.baseline:
        folder = tempfile.TemporaryDirectory(prefix="bench_identify_baseline_")
        archive = subprocess.run(
            ["git", "archive", "--format=tar", args.baseline, "spikectl"],
            cwd=REPO, check=True, capture_output=True,
        ).stdout  # fmt: skip
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(folder.name, filter="data")
        implementations = {f"baseline {args.baseline}": Worker(folder.name), **implementations}
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()  # fmt: skip
    print(f"{cpu_description()['cpu']}; {pinned}, one Numba and one BLAS thread; HEAD {commit} "
          f"(+ working tree); load average {os.getloadavg()[0]:.2f} at the start")  # fmt: skip
    print(f"IdentifyAndPlan() (defaults), {args.episodes} test episodes per n, one decision "
          "timed at a time")  # fmt: skip
    print()
    print("| n | implementation | median (ms) | p99 (ms) | max (ms) | over 1 ms | "
          "CPU p99 (ms) | CPU max (ms) | mean return |")  # fmt: skip
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    notes = []
    try:
        for n in args.n:
            results: dict[str, list[dict]] = {name: [] for name in implementations}
            for episode in range(-1, args.episodes):  # episode -1 warms up, untimed
                names = list(implementations)
                if episode % 2:
                    names.reverse()
                for name in names:
                    result = implementations[name].episode(n, max(episode, 0))
                    if episode >= 0:
                        results[name].append(result)
            table = {}
            for name, episodes in results.items():
                s = table[name] = stats(
                    [t for e in episodes for t in e["times_ns"]],
                    [t for e in episodes for t in e["cpu_ns"]], [e["return"] for e in episodes],
                )  # fmt: skip
                print(f"| {n} | {name} | {s['median']:.3f} | {s['p99']:.3f} | {s['max']:.3f} | "
                      f"{s['over_1ms']:.1%} | {s['cpu_p99']:.3f} | {s['cpu_max']:.3f} | "
                      f"{s['mean_return']:.3f} |")  # fmt: skip
            if len(results) == 2:
                (old_name, old), (_, new) = results.items()
                same = all(a["actions"] == b["actions"] for a, b in zip(old, new, strict=True))
                a, b = table[old_name], table["current"]
                notes.append(
                    f"n = {n}: baseline / current {a['median'] / b['median']:.1f}x (median), "
                    f"{a['p99'] / b['p99']:.1f}x (p99), {a['max'] / b['max']:.1f}x (max); "
                    f"same actions in every episode: {'yes' if same else 'NO'}; "
                    f"{b['decisions']} decisions each"
                )
    finally:
        for implementation in implementations.values():
            implementation.close()
        if folder is not None:
            folder.cleanup()
    if notes:
        print()
        print("\n".join(notes))
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
