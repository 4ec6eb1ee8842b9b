"""Identify-and-plan's candidate settings of the ``spikes`` composition (the exact spike
filter, :mod:`spikectl.planning.spike_filter`) for suite v2's ``spikes-only`` task, on
VALIDATION networks (never the test set), network by network against the composition
before this record, ``spikes-fast`` (the same without QMDP; paired differences, 95%
bootstrap intervals).

    python lab/results/iap-spikes/variants.py OUT_CSV [FIRST:]END VARIANT [VARIANT ...]

(validation networks FIRST .. END - 1, from 0 when FIRST is left out)

Appends one row per network and variant to OUT_CSV (``variant,context,return,cpu_s``)
and prints the paired table of every variant in OUT_CSV against ``no-qmdp``.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners import PosteriorSample
from lab.planners.screen import screen
from spikectl.planning import QMDPSettings
from spikectl.planning.named import composition

TASK = "spikes-only"
BASE = "no-qmdp"


def variants() -> dict:
    """The candidates by name: the composition before (``no-qmdp``), the named one now
    (``named``: QMDP with the core's settings) and other settings of either."""
    before = composition("spikes-fast")
    named = composition("spikes")

    def decision(**settings):
        return before.but("x", decision=dataclasses.replace(before.decision, **settings))

    table = {BASE: before, "named": named}
    for seed in (1, 2):
        table[f"named-seed{seed}"] = (named, seed)
    for networks, information in ((8, 0.03), (32, 0.03), (16, 0.0), (16, 0.1)):
        gamble = QMDPSettings(networks=networks, information=information)
        table[f"qmdp{networks}-information{information:g}"] = decision(gamble=gamble)
    for sd in (0.15, 0.2, 0.3, 0.35, 0.45):
        table[f"known_sd={sd}"] = before.but(
            "x", estimator=dataclasses.replace(before.estimator, known_sd=sd))
    table["width=64"] = decision(width=64)
    table["posterior-sample"] = before.but(
        "x", decision=PosteriorSample(**vars(before.decision)))
    return table


if __name__ == "__main__":
    first, _, last = sys.argv[2].rpartition(":")
    screen(Path(sys.argv[1]), TASK, range(int(first or 0), int(last)), variants(),
           sys.argv[3:], base=BASE)
