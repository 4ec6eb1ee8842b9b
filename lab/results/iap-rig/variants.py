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

import csv
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import IdentifyAndPlan
from spikectl.planning.estimators import ESTIMATORS, RIG_SPIKE_ESTIMATORS, SPIKE_ESTIMATORS
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


def variants() -> dict:
    """The candidates by name: the ``rig`` composition with other settings."""
    named = composition("rig")

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
    return table


def subset(networks: range) -> ContextSet:
    full = suite.load_split(TASK, SPLIT, VERSION)
    return ContextSet([full[i] for i in networks], full.params, full.seed,
                      full.extensions)  # fmt: skip


def play(contexts: ContextSet, composition) -> tuple[np.ndarray, float]:
    extensions = suite.task(TASK, VERSION).extensions
    started = time.process_time()
    episodes = evaluate_policy(contexts, IdentifyAndPlan(composition=composition,
                                                         extensions=extensions),
                               extensions=extensions,
                               seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
    return np.asarray(episodes.returns), time.process_time() - started


def main(out: Path, networks: range, names: list[str]) -> None:
    table = variants()
    contexts = subset(networks)
    new = not out.exists()
    with open(out, "a", newline="") as handle:
        writer = csv.writer(handle)
        if new:
            writer.writerow(["variant", "context", "return", "cpu_s"])
        for name in names:
            values, cpu = play(contexts, table[name])
            writer.writerows([name, i, f"{v:.6f}", f"{cpu / len(networks):.4f}"]
                             for i, v in zip(networks, values, strict=True))  # fmt: skip
            handle.flush()
            print(f"{name}: {values.mean():.4f} ({cpu:.1f} CPU s)", flush=True)
    report(out)


def report(out: Path) -> None:
    rows: dict[str, dict[int, float]] = {}
    cpu: dict[str, float] = {}
    with open(out) as handle:
        for row in csv.DictReader(handle):
            rows.setdefault(row["variant"], {})[int(row["context"])] = float(row["return"])
            cpu[row["variant"]] = float(row["cpu_s"])
    base = rows["named"]
    print(
        "\n| variant | networks | mean return | − named [95% CI] | better / worse "
        "| CPU s a network |"
    )
    print("|---|---:|---:|---|---|---:|")
    for name, values in rows.items():
        common = sorted(set(values) & set(base))
        mine = np.array([values[i] for i in common])
        theirs = np.array([base[i] for i in common])
        print(
            f"| {name} | {len(common)} | {mine.mean():.4f} | "
            f"{paired_difference_cells(mine - theirs)} | {cpu[name]:.3f} |"
        )


if __name__ == "__main__":
    first, _, last = sys.argv[2].rpartition(":")
    main(Path(sys.argv[1]), range(int(first or 0), int(last)), sys.argv[3:])
