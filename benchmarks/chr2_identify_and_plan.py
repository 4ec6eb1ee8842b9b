"""Identify-and-plan through the ChR2 actuator (docs/extensions.md, "The opsin actuator"):
mean returns on the paper task's 100 unseen test networks under
``Extensions(actuator="chr2")``.

Rows: doing nothing; identify-and-plan made for the pulse (``IdentifyAndPlan()``: it
reads each step as if a current pulse had landed and plans pulses); identify-and-plan
made for the environment (``IdentifyAndPlan(extensions=chr2)``: it tracks the opsins'
occupancies from its light, reads each step with their current and plans the light).
Each value is the mean ± its standard error over the networks, with the CPU seconds per
network. About a minute:

    python benchmarks/chr2_identify_and_plan.py
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.envs.controller import DoNothing
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.planning.named import named_composition
from spikectl.planning.policy import IdentifyAndPlan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", type=int, default=100)
    arguments = parser.parse_args()
    contexts = load_split("paper", "test")[: arguments.networks]
    n = contexts[0].n_neurons
    chr2 = Extensions(actuator="chr2")
    rows = {
        "do nothing": DoNothing(),
        "identify-and-plan, planning the pulse": IdentifyAndPlan(
            contexts.params, named_composition(None, n)),
        "identify-and-plan, planning the light": IdentifyAndPlan(
            contexts.params, named_composition(chr2, n), extensions=chr2),
    }  # fmt: skip
    print("| controller | mean return under ChR2 | CPU s / network |")
    print("|---|---:|---:|")
    for name, controller in rows.items():
        started = time.process_time()
        r = evaluate_policy(contexts, controller, extensions=chr2, seed=0).returns
        seconds = (time.process_time() - started) / len(contexts)
        print(f"| {name} | {r.mean():.4f} ± {r.std(ddof=1) / np.sqrt(r.size):.4f} | "
              f"{seconds:.2f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
