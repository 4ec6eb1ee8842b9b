"""The oracle through the ChR2 actuator (docs/extensions.md, "The opsin actuator"): mean
returns on the paper task's 100 unseen test networks under ``Extensions(actuator="chr2")``.

Rows: doing nothing; the pulse-assuming oracle (``OraclePlanner`` without a light: it
plans the paper's current pulse); the opsin-aware oracle (``OraclePlanner(...,
light_mW_per_mm2=5.0)``, the search of spikectl/planning/lit_search.py at the default
width); the same search ``--ceiling-width`` wide on the first ``--ceiling-networks`` networks
(the ceiling a search with the true model and opsin finds: a wider beam keeps more of
the sequences a narrow one drops), beside the oracle on those networks; and
the reachability bound, the return of meeting every wanted spike but those at steps 0
and 1 (a light pulse drives its neuron from the next step on, and the target, never lit,
spikes one step after its input at the earliest). Each value is the mean ± its standard
error over the networks; the seconds are CPU seconds of planning per network. Minutes:

    python benchmarks/chr2_oracle.py --ceiling-width 1024 --ceiling-networks 30
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.envs.controller import DoNothing
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.planning.oracle import DEFAULT_ORACLE_WIDTH, OraclePlanner

IRRADIANCE = 5.0
"""The fibre tip's irradiance during a pulse (mW/mm^2): the default of ``Extensions``."""


def reachability_bound(contexts) -> np.ndarray:
    """[S] every step's reward but the wanted spikes at steps 0 and 1 (each 0.5 / m)."""
    patterns = np.stack([np.asarray(c.pattern, dtype=bool) for c in contexts])
    return 1.0 - 0.5 * patterns[:, :2].sum(axis=1) / patterns.sum(axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=DEFAULT_ORACLE_WIDTH)
    parser.add_argument("--ceiling-width", type=int, default=1024)
    parser.add_argument("--networks", type=int, default=100)
    parser.add_argument("--ceiling-networks", type=int, default=30)
    arguments = parser.parse_args()
    contexts = load_split("paper", "test")[: arguments.networks]
    chr2 = Extensions(actuator="chr2", light_irradiance_mW_per_mm2=IRRADIANCE)
    rows = {
        "do nothing": DoNothing(),
        "pulse-assuming oracle": OraclePlanner(contexts, contexts.params, arguments.width),
        f"opsin-aware oracle (width {arguments.width})": OraclePlanner(
            contexts, contexts.params, arguments.width, light_mW_per_mm2=IRRADIANCE),
    }  # fmt: skip
    few = contexts[: arguments.ceiling_networks]
    returns = {}
    print("| controller | mean return under ChR2 | planning CPU s / network |")
    print("|---|---:|---:|")
    for name, controller in rows.items():
        started = time.process_time()
        returns[name] = evaluate_policy(contexts, controller, extensions=chr2, seed=0).returns
        seconds = (time.process_time() - started) / len(contexts)
        r = returns[name]
        print(f"| {name} | {r.mean():.4f} ± {r.std(ddof=1) / np.sqrt(r.size):.4f} | "
              f"{seconds:.2f} |", flush=True)  # fmt: skip
    bound = reachability_bound(contexts)
    print(f"| reachability bound | {bound.mean():.4f} ± "
          f"{bound.std(ddof=1) / np.sqrt(bound.size):.4f} | |")  # fmt: skip
    ceiling = OraclePlanner(few, contexts.params, arguments.ceiling_width,
                            light_mW_per_mm2=IRRADIANCE)  # fmt: skip
    started = time.process_time()
    ceiling_returns = evaluate_policy(few, ceiling, extensions=chr2, seed=0).returns
    seconds = (time.process_time() - started) / len(few)
    aware = returns[list(rows)[2]][: len(few)]
    gap = ceiling_returns - aware
    print(f"\nfirst {len(few)} networks: opsin-aware oracle {aware.mean():.4f}, search "
          f"ceiling (width {arguments.ceiling_width}) {ceiling_returns.mean():.4f} "
          f"({seconds:.2f} CPU s / network)")  # fmt: skip
    print(f"ceiling - oracle, network by network: {gap.mean():+.4f} ± "
          f"{gap.std(ddof=1) / np.sqrt(gap.size):.4f}; the wider search higher on "
          f"{int((gap > 1e-12).sum())}, lower on {int((gap < -1e-12).sum())} "
          f"of {gap.size}")  # fmt: skip


if __name__ == "__main__":
    main()
