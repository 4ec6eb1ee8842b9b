"""Per-decision latency of a TDRQN controlling one environment: the PyTorch step beside
the compiled policy (issue 24; docs/realtime.md).

For each n, one randomly initialised TDRQN (a fixed seed; latency does not depend on
what the weights learned) at the quick preset's sizes plays one episode on each of the
first ``--episodes`` contexts of a generated test set, one Torch thread. Each
controller plays every episode itself, the two alternating episode by episode (so both
see the same machine, and neither evicts the other's weights from the cache between
its decisions: a rig runs only one), and each decision is timed alone
(``time.perf_counter_ns``), from the environment's observation dict to an action:

- ``pytorch``: ``GreedyController`` (spikectl.agents.greedy), the path the library's
  evaluation uses, on a batch of one: ``observation_batch``, ``network.step`` under
  ``no_grad``, masked argmax, back to NumPy;
- ``compiled``: ``CompiledPolicy.act`` (spikectl.agents.compiled).

One untimed episode warms both up first. (That the two choose the same actions is
tests/test_compiled_policy.py's business.) Reports the median, p99 and max per
decision, the fraction over 1 ms, and the ratios PyTorch / compiled, all from this one
run.

``--rig-episodes K`` then runs each controller alone through the real-time rig
(``spikectl.envs.realtime.run_realtime``, 1 kHz, a missed deadline stimulates nothing)
on the first K test contexts, and reports its latency from the frame's tick, its
deadline misses and its return.

    python benchmarks/bench_compiled_policy.py [--episodes 10] [--n 8 32] [--sizes quick]
        [--rig-episodes 100]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from spikectl.agents import make_agent
from spikectl.agents.compiled import CompiledPolicy
from spikectl.agents.greedy import GreedyController
from spikectl.contexts import make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.realtime import run_realtime
from spikectl.training.machine import cpu_description
from spikectl.training.presets import QUICK

EPISODE_LENGTH = 60


def rig(n: int, episodes: int, sizes) -> list[str]:
    """Both controllers through the 1 kHz rig, one after the other: table rows."""
    torch.manual_seed(0)
    network = make_agent("tdrqn", n, EPISODE_LENGTH, sizes).eval()
    contexts = make_splits(n_train=1, n_test=episodes, n_neurons=n,
                           episode_length=EPISODE_LENGTH)[1]  # fmt: skip
    env = NeuronControlEnv(contexts=contexts)
    rows = []
    for name, controller in (
        ("pytorch", GreedyController(network)),
        ("compiled", CompiledPolicy.from_network(network)),
    ):
        run_realtime(env, controller, [0])  # warm-up
        s = run_realtime(env, controller, range(episodes)).summary()
        rows.append(
            f"| {n} | {name} | {s['median_ms']:.3f} | {s['p99_ms']:.3f} | {s['max_ms']:.3f} | "
            f"{s['misses']} of {episodes * EPISODE_LENGTH} | {s['mean_return']:.3f} |"
        )
    return rows


def measure(n: int, episodes: int, sizes) -> dict[str, np.ndarray]:
    """{controller: decision times in seconds}, every step of every episode."""
    torch.manual_seed(0)
    network = make_agent("tdrqn", n, EPISODE_LENGTH, sizes).eval()
    controllers = {"pytorch": GreedyController(network),
                   "compiled": CompiledPolicy.from_network(network)}  # fmt: skip
    contexts = make_splits(n_train=1, n_test=episodes, n_neurons=n,
                           episode_length=EPISODE_LENGTH)[1]  # fmt: skip
    env = NeuronControlEnv(contexts=contexts)
    times: dict[str, list[int]] = {name: [] for name in controllers}
    for episode in range(-1, episodes):  # episode -1 warms up, untimed
        names = list(controllers) if episode % 2 else list(controllers)[::-1]
        for name in names:
            controller = controllers[name]
            controller.reset()
            observation, info = env.reset(seed=0, options={"context": max(episode, 0)})
            done = False
            while not done:
                start = time.perf_counter_ns()
                action = controller.act(observation, info)
                elapsed = time.perf_counter_ns() - start
                if episode >= 0:
                    times[name].append(elapsed)
                observation, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
    return {name: np.array(values) * 1e-9 for name, values in times.items()}


def row(times: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(times)) * 1e3,
        "p99": float(np.percentile(times, 99)) * 1e3,
        "max": float(times.max()) * 1e3,
        "over_1ms": float(np.mean(times > 1e-3)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--n", type=int, nargs="+", default=[8, 32])
    parser.add_argument("--sizes", choices=["quick", "paper"], default="quick")
    parser.add_argument("--rig-episodes", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    sizes = QUICK.agent.sizes if args.sizes == "quick" else None
    load = os.getloadavg()[0]
    print(f"{cpu_description()['cpu']}; torch {torch.__version__}, "
          f"{torch.get_num_threads()} thread; load average {load:.2f} at the start")  # fmt: skip
    print(f"TDRQN, {args.sizes} sizes, {args.episodes} test episodes of {EPISODE_LENGTH} steps")
    print()
    print("| n | controller | median (ms) | p99 (ms) | max (ms) | over 1 ms |")
    print("|---:|---|---:|---:|---:|---:|")
    ratios = []
    for n in args.n:
        times = measure(n, args.episodes, sizes)
        stats = {name: row(values) for name, values in times.items()}
        for name, s in stats.items():
            print(f"| {n} | {name} | {s['median']:.3f} | {s['p99']:.3f} | {s['max']:.3f} | "
                  f"{s['over_1ms']:.1%} |")  # fmt: skip
        torch_s, compiled_s = stats["pytorch"], stats["compiled"]
        ratios.append(
            f"n = {n}: PyTorch / compiled {torch_s['median'] / compiled_s['median']:.1f}x "
            f"(median), {torch_s['p99'] / compiled_s['p99']:.1f}x (p99); "
            f"{times['compiled'].size} decisions each"
        )
    print()
    print("\n".join(ratios))
    if args.rig_episodes:
        print()
        print(f"Real-time rig, 1 kHz, {args.rig_episodes} test episodes per controller:")
        print()
        print("| n | controller | median (ms) | p99 (ms) | max (ms) | misses | mean return |")
        print("|---:|---|---:|---:|---:|---:|---:|")
        for n in args.n:
            print("\n".join(rig(n, args.rig_episodes, sizes)))
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
