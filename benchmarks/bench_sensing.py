"""What spikes-only sensing costs a vector step: ``sensing="spikes"`` against the paper's
potentials, interleaved.

The batched paper environment and the flat one, 4 096 environments of the paper's n = 8
(generated sets, do-nothing actions), 15 rounds of 20 steps each, the four environments
in turn; medians per step and the ratio (docs/extensions.md, "Spikes-only sensing"):

    python benchmarks/bench_sensing.py
"""

from __future__ import annotations

from bench_latency import step_seconds  # the same interleaved timing loop


def main() -> None:
    medians = step_seconds({"potentials": {"sensing": "potentials"},
                            "spikes": {"sensing": "spikes"}})  # fmt: skip
    for name in ("NeuronControlVectorEnv", "FlatNeuronControlVectorEnv"):
        plain, spikes = medians[name, "potentials"], medians[name, "spikes"]
        print(f"{name}: {plain * 1e6:.0f} us with potentials, {spikes * 1e6:.0f} us with "
              f"spikes only: x{spikes / plain:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
