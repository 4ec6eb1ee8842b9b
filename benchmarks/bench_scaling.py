"""Cost against network size: simulator, environments and context generation for n = 8 … 256.

For each n, on random topologies of the paper's rule and uniformly random actions:

- the simulator kernel through ``spikectl.neuron.simulator.advance`` (the environments' hot
  path, no input checks) on a fixed batch of networks for 60 steps: neuron-steps/s
  and µs per network-step;
- the vector environment (``NeuronControlVectorEnv``, ``num_envs`` = the batch) stepped
  with random legal actions: µs per batched step and per environment step;
- the single environment's ``step()`` (random legal actions);
- generating contexts (topology, target, pattern with its witness): ms per context.

    python benchmarks/bench_scaling.py [--batch 64] [--repeats 5] [--sizes 8 16 ...]

Prints a Markdown table of medians (docs/extensions.md records a run).
"""

from __future__ import annotations

import argparse
import platform
import time

import numba
import numpy as np
from bench_simulator import median_seconds  # a sibling script in benchmarks/

from spikectl.contexts import ContextSet
from spikectl.contexts.generation import generate_topology
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import SimulatorState, advance, as_weight_batch

SIZES = (8, 16, 32, 64, 128, 256)
STEPS = 60


def kernel_seconds(n: int, batch: int, repeats: int, rng: np.random.Generator) -> float:
    """Seconds for ``batch`` networks x STEPS steps through ``advance``."""
    params = NeuronParams()
    weights = as_weight_batch(np.stack([generate_topology(n, rng) for _ in range(batch)]))
    actions = rng.integers(-1, n, size=(batch, STEPS))
    out_voltage = np.empty((batch, STEPS, n))
    out_spikes = np.empty((batch, STEPS, n), dtype=bool)

    def run() -> None:
        state = SimulatorState.at_rest(batch, n, params)
        advance(state, weights, actions, params, out_voltage, out_spikes)

    return median_seconds(run, repeats)


def vector_step_seconds(contexts: ContextSet, batch: int, repeats: int) -> float:
    """Seconds per batched step of the vector environment with random legal actions."""
    envs = NeuronControlVectorEnv(num_envs=batch, contexts=contexts)
    envs.action_space.seed(0)
    times = []
    for repeat in range(repeats + 1):
        envs.reset(seed=repeat)
        actions = [envs.action_space.sample() for _ in range(STEPS)]
        start = time.perf_counter()
        for action in actions:
            envs.step(action)
        if repeat:  # the first episode warms up
            times.append((time.perf_counter() - start) / STEPS)
    return float(np.median(times))


def single_step_seconds(contexts: ContextSet, repeats: int) -> float:
    """Seconds per ``step()`` of the single environment with random legal actions."""
    env = NeuronControlEnv(contexts=contexts)
    env.action_space.seed(0)
    times = []
    for repeat in range(repeats + 1):
        env.reset(seed=repeat)
        actions = [int(env.action_space.sample()) for _ in range(STEPS)]
        start = time.perf_counter()
        for action in actions:
            env.step(action)
        if repeat:
            times.append((time.perf_counter() - start) / STEPS)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=64, help="networks / vector envs")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--contexts", type=int, default=20, help="contexts generated per n")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"numba {numba.__version__}, {numba.get_num_threads()} threads, {platform.processor()}")
    print(f"batch {args.batch}, {STEPS} steps, medians of {args.repeats}\n")
    print(
        "| n | kernel (M neuron-steps/s) | kernel (µs per network-step) "
        f"| vector env step, {args.batch} envs (µs) | µs per env step (vector) "
        "| single env step (µs) | context generation (ms each) |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        seconds = kernel_seconds(n, args.batch, args.repeats, rng)
        network_steps = args.batch * STEPS
        start = time.perf_counter()
        contexts = ContextSet.generate(args.contexts, n_neurons=n, seed=n)
        generation_ms = (time.perf_counter() - start) / args.contexts * 1e3
        vector = vector_step_seconds(contexts, args.batch, args.repeats)
        single = single_step_seconds(contexts, args.repeats)
        print(
            f"| {n} | {network_steps * n / seconds / 1e6:.1f} "
            f"| {seconds / network_steps * 1e6:.3f} | {vector * 1e6:.0f} "
            f"| {vector / args.batch * 1e6:.2f} | {single * 1e6:.1f} | {generation_ms:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
