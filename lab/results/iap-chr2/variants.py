"""Identify-and-plan's candidate compositions for suite v2's ``chr2`` task, on the first
NETWORKS networks of its VALIDATION set (never the test set), network by network against
the named controller (paired differences, 95% bootstrap intervals).

    python lab/results/iap-chr2/variants.py OUT_CSV [FIRST:]END VARIANT [VARIANT ...]

(validation networks FIRST .. END - 1, from 0 when FIRST is left out)

Appends one row per network and variant to OUT_CSV (``variant,context,return,cpu_s``)
and prints the paired table of every variant in OUT_CSV against ``named``.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.screen import screen
from spikectl.planning import DecisionSettings, PlanningModel, ProberSettings
from spikectl.planning.named import composition

TASK, SPLIT, VERSION = "chr2", "validation", 2
DO_NOTHING = -1  # the simulator's action for no stimulation


@dataclasses.dataclass(frozen=True)
class NeverProbe(ProberSettings):
    """Diagnostic: never probe (identify only from what the plans stimulate)."""

    def choose(self, estimate, known_sd, known, ready, target, mask) -> int:
        return DO_NOTHING


@dataclasses.dataclass(frozen=True)
class LeastLikelyFirst(ProberSettings):
    """Diagnostic: probe the unknown row least likely to excite the target first (a
    light pulse drives a burst, so probing a likely input drives the target again and
    again)."""

    def choose(self, estimate, known_sd, known, ready, target, mask) -> int:
        candidates = ready & ~known.all(axis=1) & mask[1:]
        if not candidates.any():
            return DO_NOTHING
        score = -estimate.excitation_probability(target, known_sd)
        score = score + self.unknown_entry_bonus * (~known).sum(axis=1)
        score[~candidates] = -np.inf
        return int(np.argmax(score))


@dataclasses.dataclass(frozen=True)
class SampledInputs(DecisionSettings):
    """Plans each light sequence for its mean return over networks that differ in the
    target's unknown inputs, drawn from the estimate (the episode's uniforms: common
    random numbers), the rest at the planning weights: a light is timed for where an
    unknown input would hit a wanted spike."""

    hypotheses: int = 8

    @property
    def draws(self) -> int:
        return self.hypotheses

    def planning_model(self, policy, weights, situation) -> PlanningModel:
        target = situation.target
        drawn = policy.estimate.sample(policy.known_sd, *policy.uniforms)[:, :, target]
        unknown = ~policy.planning_weights()[1][:, target]
        columns = np.where(unknown[None], drawn, weights[None, :, target])
        columns = np.unique(columns, axis=0)
        networks = np.repeat(weights[None], columns.shape[0], axis=0)
        networks[:, :, target] = columns
        return PlanningModel(
            np.ascontiguousarray(networks, dtype=np.float64),
            target,
            situation.actions,
            policy.params,
            policy.planned_neurons(),
        )


def variants() -> dict:
    """The candidates by name: compositions on the named one."""
    # "named": what the named controller played on chr2 before this record (the paper's
    # composition); the chosen form is "kind=bayes", the ``chr2`` composition now.
    named = composition("paper")

    def estimator(**settings):
        return named.but("x", estimator=dataclasses.replace(named.estimator, **settings))

    def decision(**settings):
        return named.but("x", decision=dataclasses.replace(named.decision, **settings))

    table = {"named": named}
    for sd in (0.3, 0.35, 0.4, 0.45, 0.5):
        table[f"known_sd={sd}"] = estimator(known_sd=sd)
    for kind in ("bayes", "particles"):
        table[f"kind={kind}"] = estimator(kind=kind)
        for sd in (0.35, 0.4):
            table[f"kind={kind},known_sd={sd}"] = estimator(kind=kind, known_sd=sd)
    for width in (16, 64):
        table[f"width={width}"] = decision(width=width)
    table["kind=bayes,width=64"] = named.but(
        "x",
        estimator=dataclasses.replace(named.estimator, kind="bayes"),
        decision=dataclasses.replace(named.decision, width=64),
    )
    for k in (4, 8, 16):
        table[f"sampled-inputs={k}"] = named.but("x", decision=SampledInputs(hypotheses=k))
    # The chosen composition (now ``chr2``) planning on K networks drawn from the exact
    # posterior, as the ``rig`` composition does (2026-11-30, docs/results/iap-rig).
    table["kind=bayes,hypotheses=8"] = table["kind=bayes"].but(
        "x", decision=dataclasses.replace(named.decision, hypotheses=8))
    table["never-probe"] = named.but("x", prober=NeverProbe())
    table["least-likely-first"] = named.but("x", prober=LeastLikelyFirst())
    for horizon in (10, 30, None):
        table[f"horizon={horizon}"] = decision(horizon=horizon)
    return table


if __name__ == "__main__":
    first, _, last = sys.argv[2].rpartition(":")
    screen(Path(sys.argv[1]), TASK, range(int(first or 0), int(last)), variants(),
           sys.argv[3:])
