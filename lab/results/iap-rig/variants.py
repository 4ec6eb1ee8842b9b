"""Identify-and-plan's candidate settings of the ``rig`` composition (the spike likelihood,
:mod:`spikectl.planning.spike_likelihood`) for suite v2's ``rig`` task, on VALIDATION
networks (never the test set), network by network against the ``rig`` composition as
committed (paired differences, 95% bootstrap intervals).

    python lab/results/iap-rig/variants.py OUT_CSV [FIRST:]END VARIANT [VARIANT ...]

(validation networks FIRST .. END - 1, from 0 when FIRST is left out)

Appends one row per network and variant to OUT_CSV (``variant,context,return,cpu_s``)
and prints the paired table of every variant in OUT_CSV against ``named``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.screen import screen
from spikectl.planning.estimators import (
    ESTIMATORS,
    RIG_SPIKE_ESTIMATORS,
    SPIKE_ESTIMATORS,
    EstimatorSettings,
)
from spikectl.planning.named import composition
from spikectl.planning.spike_likelihood import MISS_PROBABILITY, PRUNE_NATS, SpikeLikelihoodFilter

TASK, SPLIT, VERSION = "rig", "validation", 2


def likelihood(miss: float = MISS_PROBABILITY, prune: float = PRUNE_NATS, scale: float = 1.0,
               floor: float | None = None):
    """A spike-likelihood estimator with other settings: ``scale`` multiplies the
    background rate it assumes; ``floor`` (a multiple of the chance of one spontaneous
    input) is the least an unexplained spike is charged (None: that chance, whatever
    the distance to the threshold)."""

    def new(n, residual_sd, model, params):
        rate = -math.log1p(-model.background_probability) * scale
        least = None if floor is None else floor * -math.expm1(-rate)
        step_mV = model.background_step * params.synaptic_step_mV
        return SpikeLikelihoodFilter(n, params, rate, step_mV, miss, prune, least)

    return new


@dataclasses.dataclass(frozen=True)
class PlanKnownOnly(EstimatorSettings):
    """Unknown entries planned as 0, not at their posterior mean (the plan lights only
    what the estimate knows drives the target)."""

    def planning_weights(self, estimate, plan_mean, strengths, relayed):
        return super().planning_weights(estimate, False, strengths, relayed)


def variants() -> dict:
    """The candidates by name: the ``rig`` composition with other settings. ``named`` is
    the composition as first committed, planning on the estimate alone (the rows of
    screen100.csv and validation200.csv); the ``rig`` composition now plans on
    ``hypotheses=8`` (``RIG_HYPOTHESES``)."""
    chosen = composition("rig")
    named = chosen.but("rig", decision=dataclasses.replace(chosen.decision, hypotheses=1))

    def estimator(kind: str, factory=None, **settings):
        if factory is not None and kind not in ESTIMATORS:
            ESTIMATORS.register(kind, factory)
            RIG_SPIKE_ESTIMATORS.add(kind)
            SPIKE_ESTIMATORS.add(kind)
        return named.but("x", estimator=dataclasses.replace(named.estimator, kind=kind,
                                                            **settings))  # fmt: skip

    table = {"named": named}
    for miss in (1e-2, 1e-5):
        table[f"miss={miss:g}"] = estimator(f"sl-miss{miss:g}", likelihood(miss=miss))
    for prune in (8.0, 30.0):
        table[f"prune={prune:g}"] = estimator(f"sl-prune{prune:g}", likelihood(prune=prune))
    for scale in (0.2, 4.0):
        table[f"scale={scale:g}"] = estimator(f"sl-scale{scale:g}", likelihood(scale=scale))
    for floor in (0.1, 0.01):
        table[f"floor={floor:g}"] = estimator(f"sl-floor{floor:g}", likelihood(floor=floor))
    for sd in (0.15, 0.35):
        table[f"known_sd={sd}"] = estimator("spike-likelihood", known_sd=sd)
    for width in (16, 64):
        table[f"width={width}"] = named.but(
            "x", decision=dataclasses.replace(named.decision, width=width))
    for k in (4, 8, 16):
        table[f"hypotheses={k}"] = named.but(
            "x", decision=dataclasses.replace(named.decision, hypotheses=k))
    for seed in (1, 2):  # the draws of other controller seeds
        table[f"hypotheses=8,seed={seed}"] = (table["hypotheses=8"], seed)
    table["known-only"] = named.but("x", estimator=PlanKnownOnly(
        named.estimator.kind, named.estimator.known_sd))
    return table


if __name__ == "__main__":
    first, _, last = sys.argv[2].rpartition(":")
    screen(Path(sys.argv[1]), TASK, range(int(first or 0), int(last)), variants(),
           sys.argv[3:])
