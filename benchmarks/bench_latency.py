"""What loop latency costs a vector step: ``latency_steps`` 2 against 0, interleaved.

The batched paper environment and the flat one, 4 096 environments of the paper's n = 8
(generated sets, do-nothing actions: the queue's cost does not depend on them), 15
rounds of 20 steps each, the four environments in turn; medians per step and the ratio
(docs/extensions.md, "Loop latency"):

    python benchmarks/bench_latency.py
"""

from __future__ import annotations

import time

import numpy as np

from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers.flat_vector_env import FlatNeuronControlVectorEnv

BATCH, ROUNDS, STEPS, LATENCY = 4096, 15, 20, 2


def step_seconds(settings: dict[str, dict]) -> dict[tuple[str, str], float]:
    """Median seconds per step of the paper and flat vector envs under each named
    ``extensions`` setting, the environments stepped in turn (interleaved rounds)."""
    envs = {}
    for cls, do_nothing in ((NeuronControlVectorEnv, -1), (FlatNeuronControlVectorEnv, 0)):
        for label, extensions in settings.items():
            env = cls(BATCH, contexts={"n_train": 100, "n_test": 10}, extensions=extensions)
            env.reset(seed=0)
            envs[cls.__name__, label] = (env, np.full(BATCH, do_nothing, dtype=np.int64))
    seconds: dict[tuple[str, str], list[float]] = {key: [] for key in envs}
    for _ in range(ROUNDS):
        for key, (env, actions) in envs.items():
            started = time.perf_counter()
            for _ in range(STEPS):
                env.step(actions)
            seconds[key].append((time.perf_counter() - started) / STEPS)
    return {key: float(np.median(values)) for key, values in seconds.items()}


def main() -> None:
    medians = step_seconds({"0": {"latency_steps": 0}, "L": {"latency_steps": LATENCY}})
    for name in ("NeuronControlVectorEnv", "FlatNeuronControlVectorEnv"):
        plain, delayed = medians[name, "0"], medians[name, "L"]
        print(f"{name}: {plain * 1e6:.0f} us without latency, {delayed * 1e6:.0f} us with "
              f"latency_steps={LATENCY}: x{delayed / plain:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
