"""Identify-and-plan settings on a suite task's split: mean return, normalised score,
CPU s per episode and per-decision CPU-time percentiles, one line per (task, setting).

    python lab/results/bayes-identify/sweep.py --tasks paper noise2 --split validation \
        --settings '{}' '{"identification": "bayes", "extensions": true}' [--size 30] \
        [--out rows.csv] [--per-network out.csv]

A setting is a composition of identify-and-plan as JSON, in the words of the research
record (:func:`composition_of`): "identification" (the estimator), "extensions": true (the
task's observation model), "filter_voltage", "gamble_networks" (QMDP's K), "known_sd",
"width"; {"named": true} is what `spikectl benchmark identify-and-plan` plays
(spikectl.planning.named_composition of the task), the other keys on top of it.

Choose on validation (a training split checks a choice on more unseen networks); the
test split is played once, at the end.
"""

from __future__ import annotations

import argparse
import csv
import json
import time

import numpy as np

from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import (
    Composition,
    DecisionSettings,
    EstimatorSettings,
    IdentifyAndPlan,
    ObservationSettings,
    QMDPSettings,
    named_composition,
)


class Timed:
    """Wraps a controller, recording the CPU time of every decision (the thread's
    clock: on a shared machine wall time measures the neighbours, not the decision)."""

    def __init__(self, policy, times=None):
        self.policy, self.times = policy, ([] if times is None else times)

    def spawn(self, index):
        return Timed(self.policy.spawn(index), self.times)

    def reset(self):
        self.policy.reset()

    def act(self, observation, info):
        started = time.thread_time()
        action = self.policy.act(observation, info)
        self.times.append(time.thread_time() - started)
        return action


def composition_of(text: str, extensions, n_neurons: int) -> Composition:
    """The composition a ``--settings`` JSON names (its text is the composition's name)."""
    settings = json.loads(text)
    named = settings.pop("named", False)
    base = named_composition(extensions, n_neurons) if named else Composition()
    estimator, observation, decision = base.estimator, base.observation, base.decision
    if "identification" in settings or "known_sd" in settings:
        kind = settings.pop("identification", estimator.kind)
        estimator = EstimatorSettings(kind, settings.pop("known_sd", estimator.known_sd))
    if "extensions" in settings or "filter_voltage" in settings:
        task_model = settings.pop("extensions", observation.task_model)
        filtered = settings.pop("filter_voltage", observation.filter_voltage)
        observation = ObservationSettings(task_model, filtered)
    if "gamble_networks" in settings or "width" in settings:
        networks = settings.pop("gamble_networks", decision.draws)
        gamble = QMDPSettings(networks=networks) if networks else None
        decision = DecisionSettings(settings.pop("width", decision.width), decision.horizon, gamble)
    if settings:
        raise SystemExit(f"--settings {text}: unknown keys {', '.join(settings)}")
    return base.but(text, estimator=estimator, observation=observation, decision=decision)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tasks", nargs="+", default=["paper"])
    parser.add_argument("--split", default="validation", choices=("train", "validation", "test"))
    parser.add_argument("--settings", nargs="+", default=["{}"])
    parser.add_argument("--size", type=int, default=100)
    parser.add_argument("--per-network", default=None)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    rows, per_network = [], []
    for name in args.tasks:
        spec = suite.task(name)
        contexts = suite.load_split(name, args.split)
        if args.size < len(contexts):
            contexts = contexts[: args.size]
        # Normalised scores on the validation and test sets only (a training set is a
        # check of a choice; its oracle would cost minutes per task).
        scored = args.size >= 100 and args.split != "train"
        nothing, oracle = suite.references(name, args.split) if scored else (None, None)
        for text in args.settings:
            composition = composition_of(text, spec.extensions, contexts.n_observed)
            policy = Timed(IdentifyAndPlan(contexts.params, composition,
                                           extensions=spec.extensions))  # fmt: skip
            started = time.process_time()
            episodes = evaluate_policy(
                contexts, policy, extensions=spec.extensions, seed=suite.suite_version(1).env_seed
            )
            cpu = time.process_time() - started
            mean = float(episodes.returns.mean())
            norm = suite.normalise(mean, nothing, oracle) if nothing is not None else float("nan")
            times = np.array(policy.times) * 1e3
            row = {
                "task": name,
                "split": args.split,
                "settings": text,
                "contexts": len(contexts),
                "mean_return": round(mean, 6),
                "normalised": round(norm, 6),
                "cpu_s_per_episode": round(cpu / len(contexts), 4),
                "decision_cpu_ms_p50": round(float(np.percentile(times, 50)), 4),
                "decision_cpu_ms_p99": round(float(np.percentile(times, 99)), 4),
            }
            rows.append(row)
            print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)
            per_network += [
                {
                    "task": name,
                    "split": args.split,
                    "settings": text,
                    "context": i,
                    "return": round(float(r), 6),
                }
                for i, r in enumerate(episodes.returns)
            ]
    for path, table in ((args.out, rows), (args.per_network, per_network)):
        if path:
            with open(path, "w", newline="") as handle:
                writer = csv.DictWriter(handle, fieldnames=list(table[0]))
                writer.writeheader()
                writer.writerows(table)


if __name__ == "__main__":
    main()
