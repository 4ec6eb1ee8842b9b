"""What spikes-only sensing costs a vector step: ``sensing="spikes"`` against the paper's
potentials, interleaved.

The batched paper environment and the flat one, 4 096 environments of the paper's n = 8
(generated sets, do-nothing actions), 15 rounds of 20 steps each, the four environments
in turn; medians per step and the ratio (docs/extensions.md, "Spikes-only sensing"):

    python benchmarks/bench_sensing.py
"""

from __future__ import annotations

import time

import numpy as np

from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers.flat_vector_env import FlatNeuronControlVectorEnv

BATCH, ROUNDS, STEPS = 4096, 15, 20
MODES = ("potentials", "spikes")


def main() -> None:
    envs = {}
    for cls, do_nothing in ((NeuronControlVectorEnv, -1), (FlatNeuronControlVectorEnv, 0)):
        for sensing in MODES:
            env = cls(BATCH, contexts={"n_train": 100, "n_test": 10},
                      extensions={"sensing": sensing})  # fmt: skip
            env.reset(seed=0)
            envs[cls.__name__, sensing] = (env, np.full(BATCH, do_nothing, dtype=np.int64))
    seconds: dict[tuple[str, str], list[float]] = {key: [] for key in envs}
    for _ in range(ROUNDS):
        for key, (env, actions) in envs.items():
            started = time.perf_counter()
            for _ in range(STEPS):
                env.step(actions)
            seconds[key].append((time.perf_counter() - started) / STEPS)
    for name in ("NeuronControlVectorEnv", "FlatNeuronControlVectorEnv"):
        plain, spikes = (float(np.median(seconds[name, sensing])) for sensing in MODES)
        print(f"{name}: {plain * 1e6:.0f} us with potentials, {spikes * 1e6:.0f} us with "
              f"spikes only: x{spikes / plain:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
