"""What spikes-only sensing costs a vector step: ``sensing="spikes"`` (and with a recorded
subset, ``recorded_neurons=4``) against the paper's potentials, interleaved.

The batched paper environment and the flat one, 4 096 environments of the paper's n = 8
(generated sets, do-nothing actions), 15 rounds of 20 steps each, the six environments
in turn; medians per step and the ratios (docs/extensions.md, "Spikes-only sensing"):

    python benchmarks/bench_sensing.py
"""

from __future__ import annotations

from bench_latency import step_seconds  # the same interleaved timing loop

RECORDED = 4


def main() -> None:
    medians = step_seconds({
        "potentials": {"sensing": "potentials"},
        "spikes": {"sensing": "spikes"},
        "recorded": {"sensing": "spikes", "recorded_neurons": RECORDED},
    })  # fmt: skip
    for name in ("NeuronControlVectorEnv", "FlatNeuronControlVectorEnv"):
        plain, spikes = medians[name, "potentials"], medians[name, "spikes"]
        recorded = medians[name, "recorded"]
        print(f"{name}: {plain * 1e6:.0f} us with potentials, {spikes * 1e6:.0f} us with "
              f"spikes only: x{spikes / plain:.3f}; {recorded * 1e6:.0f} us with "
              f"{RECORDED} of 8 recorded: x{recorded / plain:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
