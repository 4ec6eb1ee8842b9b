"""The oracle under loop latency (docs/extensions.md, "Loop latency"): mean returns on the
paper task's unseen test networks for latency_steps 0, 1, 2 (or --latencies): suite v1's
100 networks, or suite v2's 1 000 with ``--suite 2``.

Rows: doing nothing; the latency-unaware oracle (``OraclePlanner(latency_steps=0)``, its
latency-0 plan landing late); the latency-aware oracle (``OraclePlanner``, which reads the
latency from the observation); and the ceiling, the return of meeting every wanted spike
a loop of that latency can reach (none at steps 0 .. L: nothing lands before step L and
the target, never stimulated, spikes one step after its input at the earliest). Each
value is the mean ± its standard error over the networks; "normalised" is
(R - do nothing) / (ceiling - do nothing). A few CPU seconds (about a minute with
``--suite 2``):

    python benchmarks/latency_oracle.py [--suite 2]
"""

from __future__ import annotations

import argparse

import numpy as np

from spikectl.envs.controller import DoNothing
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.planning.oracle import DEFAULT_ORACLE_WIDTH, OraclePlanner


def ceiling(contexts, latency: int) -> np.ndarray:
    """[S] the best return a loop of ``latency`` steps allows: every step's reward but
    the wanted spikes at steps 0 .. latency (each worth 0.5 / m)."""
    patterns = np.stack([np.asarray(c.pattern, dtype=bool) for c in contexts])
    return 1.0 - 0.5 * patterns[:, : latency + 1].sum(axis=1) / patterns.sum(axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--latencies", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--width", type=int, default=DEFAULT_ORACLE_WIDTH)
    parser.add_argument("--suite", type=int, choices=[1, 2], default=1,
                        help="whose test networks: suite v1's (100) or v2's (1 000)")
    arguments = parser.parse_args()
    contexts = load_split("paper", "test", version=arguments.suite)
    aware = OraclePlanner(contexts, contexts.params, arguments.width)
    unaware = OraclePlanner(contexts, contexts.params, arguments.width, latency_steps=0)
    print("| latency | do nothing | unaware oracle | aware oracle | ceiling | aware, normalised |")
    print("|---:|---:|---:|---:|---:|---:|")
    for latency in arguments.latencies:
        extensions = Extensions(latency_steps=latency)
        returns = {
            name: evaluate_policy(contexts, controller, extensions=extensions, seed=0).returns
            for name, controller in (("nothing", DoNothing()), ("unaware", unaware),
                                     ("aware", aware))  # fmt: skip
        }
        returns["ceiling"] = ceiling(contexts, latency)
        cells = [f"{r.mean():.4f} ± {r.std(ddof=1) / np.sqrt(r.size):.4f}"
                 for r in returns.values()]  # fmt: skip
        gained = (returns["aware"] - returns["nothing"]).mean()
        reachable = (returns["ceiling"] - returns["nothing"]).mean()
        print(f"| {latency} | " + " | ".join(cells) + f" | {gained / reachable:.4f} |")


if __name__ == "__main__":
    main()
