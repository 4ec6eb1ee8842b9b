"""Where identify-and-plan loses on suite v2's ``rig`` task: on the first NETWORKS
networks of the VALIDATION set (never the test set), network by network, the ``rig``
composition; the same told the true weights (the spike likelihood restricted to each
neuron's true input column: the potentials are still read from spikes alone, so what
is left is the loop's and the sensing's cost, not identification's); and both on the same
networks without the background input (what the spontaneous inputs cost); with
``target``, the same told the target's true input column alone, and every column but
the target's (2026-11-30).

    python lab/results/iap-rig/diagnose.py OUT_DIR [NETWORKS] [target]

Writes OUT_DIR/diagnose-per-network.csv (with ``target``: the ``rig`` composition and the
loops told the target's column or the others', OUT_DIR/diagnose-target-per-network.csv)
and prints the paired table.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.screen import diagnose, subset
from lab.planners.told import ToldColumns
from spikectl.experiments import suite
from spikectl.planning import IdentifyAndPlan
from spikectl.planning.named import composition

TASK, VERSION = "rig", 2


def main(out: Path, networks: int, target: bool = False) -> None:
    contexts = subset(TASK, range(networks))
    rig = suite.task(TASK, VERSION).extensions
    quiet = dataclasses.replace(rig, background_rate=0.0)
    named = composition("rig")
    runs = {
        "named": (rig, IdentifyAndPlan(composition=named, extensions=rig)),
        "told": (rig, ToldColumns(contexts, composition=named, extensions=rig)),
        "named-no-background": (quiet, IdentifyAndPlan(composition=named, extensions=quiet)),
        "told-no-background": (quiet, ToldColumns(contexts, composition=named, extensions=quiet)),
    }
    if target:
        runs = {"named": runs["named"]} | {
            f"told-{columns}": (rig, ToldColumns(contexts, columns, composition=named,
                                                 extensions=rig))
            for columns in ("target", "others")
        }  # fmt: skip
    name = "diagnose-target-per-network.csv" if target else "diagnose-per-network.csv"
    diagnose(out / name, contexts, runs, "named")


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 100,
         sys.argv[3:] == ["target"])
