"""Where identify-and-plan loses on suite v2's ``chr2`` task: on a fixed subset of the
VALIDATION set (never the test set), network by network, the named controller as it was
(the paper's composition), the same with the exact posterior (the ``chr2`` composition
now), the same loop told the true weights, and the oracle; and how much of the network
each estimate knows, and how rightly, at steps 10, 30 and 59.

    python lab/results/iap-chr2/diagnose.py docs/results/iap-chr2 [NETWORKS [TASK]]

(TASK: ``chr2``, or ``paper`` for the same networks through the current pulse.)
"""

from __future__ import annotations

import csv
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.recording import RecordingIdentifyAndPlan
from lab.planners.told import Told
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import (
    DEFAULT_ORACLE_WIDTH,
    EstimatorSettings,
    OraclePlanner,
)
from spikectl.planning.named import composition

SPLIT, VERSION = "validation", 2
TASK = sys.argv[3] if len(sys.argv) > 3 else "chr2"
CHECKED_STEPS = RecordingIdentifyAndPlan.checked_steps


def subset(networks: int) -> ContextSet:
    """The first ``networks`` networks of v2's chr2 validation set."""
    full = suite.load_split(TASK, SPLIT, VERSION)
    return ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                      full.extensions)  # fmt: skip


def play(contexts: ContextSet, controller) -> tuple[np.ndarray, float]:
    started = time.process_time()
    episodes = evaluate_policy(contexts, controller,
                               extensions=suite.task(TASK, VERSION).extensions,
                               seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
    return np.asarray(episodes.returns), time.process_time() - started


def light(extensions) -> float | None:
    """The irradiance the oracle plans the light of (None: the current pulse)."""
    return extensions.light_irradiance_mW_per_mm2 if extensions.actuator == "chr2" else None


class Checked(RecordingIdentifyAndPlan):
    """Records, at :data:`CHECKED_STEPS`, the share of off-diagonal weights its estimate
    calls known, the share of those that are right, and the share of all off-diagonal
    planning weights (rounded) that equal the truth, and the probes it took."""

    def measure(self, step, signs, known, truth) -> tuple:
        off = ~np.eye(known.shape[0], dtype=bool)
        right = (signs[known] == truth[known]).mean() if known.any() else 1.0
        planned = np.round(self.planning_weights()[0])
        agree = (planned[off] == truth[off]).mean()
        return step, known.sum() / off.sum(), right, agree, self.probes


def main(out: Path, networks: int) -> None:
    contexts = subset(networks)
    extensions = suite.task(TASK, VERSION).extensions
    named = composition("paper")  # what the named controller played on chr2 before
    oracle = OraclePlanner(contexts, contexts.params, DEFAULT_ORACLE_WIDTH,
                           extensions.allow_target_action,
                           light_mW_per_mm2=light(extensions))  # fmt: skip
    records: dict[str, list] = {"paper's (Gaussian)": [], "exact posterior (bayes)": []}
    results = {
        "identify-and-plan (named)": play(
            contexts,
            Checked(
                contexts, records["paper's (Gaussian)"], composition=named, extensions=extensions
            ),
        )
    }
    exact = named.but("bayes", estimator=EstimatorSettings("bayes"))
    results["the exact posterior"] = play(
        contexts,
        Checked(
            contexts, records["exact posterior (bayes)"], composition=exact, extensions=extensions
        ),
    )
    results["told the true weights"] = play(
        contexts, Told(contexts, composition=named, extensions=extensions)
    )
    results["oracle"] = play(contexts, oracle)
    base = results["identify-and-plan (named)"][0]
    print(f"{TASK} validation, first {networks} networks, network by network:\n")
    print("| controller | mean return | − named [95% CI] | better / worse | CPU s |")
    print("|---|---:|---|---|---:|")
    for label, (values, cpu) in results.items():
        print(f"| {label} | {values.mean():.3f} | {paired_difference_cells(values - base)} "
              f"| {cpu:.1f} |")  # fmt: skip
    print(
        "\nThe estimate (off the diagonal): share known / share of those right / "
        "planning weights equal to the truth / probes so far\n"
    )
    print("| estimate | step | known | right | planned = truth | probes |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, record in records.items():
        rec = np.array(record)
        for step in CHECKED_STEPS:
            at = rec[rec[:, 0] == step]
            print(
                f"| {label} | {step} | {at[:, 1].mean():.2f} | {at[:, 2].mean():.3f} | "
                f"{at[:, 3].mean():.3f} | {at[:, 4].mean():.2f} |"
            )
    with open(out / f"diagnose-{TASK}-per-network.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["controller", "split", "context", "return"])
        for label, (values, _) in results.items():
            writer.writerows([label, SPLIT, i, f"{v:.6f}"] for i, v in enumerate(values))


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 50)
