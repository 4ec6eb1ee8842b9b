"""Batched simulator throughput in neuron-steps per second.

Times ``spikectl.simulate`` (input checks and output allocation included) on random
topologies and random actions for several batch sizes and network sizes, beside a
plain vectorised NumPy implementation of the same step measured in the same run
(the baseline the Numba kernel replaced; it is checked against the kernel first).

    python benchmarks/bench_simulator.py [--repeats 7] [--steps 60] [--json out.json]

Prints a Markdown table of medians; docs/benchmarks.md records a run.
"""

from __future__ import annotations

import argparse
import platform
import time

import numba
import numpy as np

from spikectl import NeuronParams, simulate
from spikectl.contexts.generation import generate_topology
from spikectl.files import write_json

CASES = [
    (1, 8),
    (64, 8),
    (4096, 8),
    (1, 64),
    (64, 64),
    (4096, 64),
    (1, 256),
    (64, 256),
    (4096, 256),
]


def numpy_baseline(weights: np.ndarray, actions: np.ndarray, params: NeuronParams) -> np.ndarray:
    """The same dynamics as whole-array NumPy operations per step (for comparison only)."""
    batch, steps = actions.shape
    n = weights.shape[1]
    v = np.full((batch, n), params.v_rest_mV)
    refractory = np.zeros((batch, n), dtype=bool)
    since = np.full((batch, n), 2**30)
    released = np.zeros((batch, n))
    leak = params.dt_ms / params.membrane_time_constant_ms
    stimulus = params.dt_ms * params.stimulus_current_pA / params.capacitance_pF
    synaptic = params.dt_ms * params.synaptic_current_pA / params.capacitance_pF
    threshold = params.v_threshold_mV - params.threshold_tolerance_mV
    interval = params.min_release_interval_steps
    rows = np.arange(batch)
    out = np.empty((batch, steps, n))
    for t in range(steps):
        drive = synaptic * np.einsum("bi,bij->bj", released, weights)  # [B, n]
        act = actions[:, t]
        stimulated = act >= 0
        drive[rows[stimulated], act[stimulated]] += stimulus
        since = np.minimum(since + 1, 2**30)
        v = np.where(refractory, params.v_rest_mV, v + (-(v - params.v_rest_mV) * leak + drive))
        spiked = ~refractory & (v >= threshold)
        out[:, t] = v
        release = spiked & (since >= interval)
        since = np.where(release, 0, since)
        released = release.astype(np.float64)
        v = np.where(spiked, params.v_rest_mV, v)
        refractory = spiked
    return out


def median_seconds(function, repeats: int) -> float:
    function()  # warm-up: JIT compilation, page faults
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--steps", type=int, default=60, help="steps per simulate() call")
    parser.add_argument("--json", type=str, default=None, help="also write results here")
    args = parser.parse_args()
    params = NeuronParams()
    rng = np.random.default_rng(0)
    results = []
    print(f"numba {numba.__version__}, {numba.get_num_threads()} threads, {platform.processor()}")
    print("| batch | n | spikectl (M neuron-steps/s) | NumPy baseline (M/s) | ratio |")
    print("|---:|---:|---:|---:|---:|")
    for batch, n in CASES:
        weights = np.stack([generate_topology(n, rng) for _ in range(batch)])
        actions = rng.integers(-1, n, size=(batch, args.steps))
        neuron_steps = batch * args.steps * n
        kernel_seconds = median_seconds(
            lambda w=weights, a=actions: simulate(w, a, params), args.repeats
        )
        baseline_weights = weights.astype(np.float64)
        np.testing.assert_array_equal(
            simulate(weights, actions, params)[0], numpy_baseline(baseline_weights, actions, params)
        )
        baseline_seconds = median_seconds(
            lambda w=baseline_weights, a=actions: numpy_baseline(w, a, params),
            max(3, args.repeats // 2),
        )
        row = {
            "batch": batch,
            "n": n,
            "steps": args.steps,
            "spikectl_neuron_steps_per_s": neuron_steps / kernel_seconds,
            "numpy_neuron_steps_per_s": neuron_steps / baseline_seconds,
        }
        results.append(row)
        kernel_rate = row["spikectl_neuron_steps_per_s"] / 1e6
        baseline_rate = row["numpy_neuron_steps_per_s"] / 1e6
        print(
            f"| {batch} | {n} | {kernel_rate:.1f} | {baseline_rate:.1f} | "
            f"{baseline_seconds / kernel_seconds:.1f}x |",
            flush=True,
        )
    if args.json:
        write_json(args.json, results)


if __name__ == "__main__":
    main()
