"""What the distance prior is worth to identify-and-plan: the planner with its prior on
each synapse (the generator's connection probability of |i - j|) against the same
planner told only the mean connection probability (every pair alike, as a
permutation-equivariant network without positions sees them), on a task's validation
networks (never the test set).

    python lab/results/student-n32-diagnosis/planner_without_geometry.py --task n32
"""

from __future__ import annotations

import argparse

import numpy as np

from spikectl import IdentifyAndPlan
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.stats import bootstrap_ci
from spikectl.experiments.suite import load_split
from spikectl.planning import identify


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="n32")
    args = parser.parse_args()
    contexts = load_split(args.task, "validation")
    n = contexts.n_observed
    with_prior = evaluate_policy(contexts, IdentifyAndPlan()).returns
    distance = np.abs(np.arange(n)[:, None] - np.arange(n)[None, :])
    off_diagonal = ~np.eye(n, dtype=bool)
    mean_probability = identify.connection_probability(distance)[off_diagonal].mean()
    by_distance = identify.connection_probability
    identify.connection_probability = lambda d: np.full(np.shape(d), mean_probability)
    identify.ConnectivityEstimate._PRIORS.clear()
    try:
        without = evaluate_policy(contexts, IdentifyAndPlan()).returns
    finally:
        identify.connection_probability = by_distance
        identify.ConnectivityEstimate._PRIORS.clear()
    difference = without - with_prior
    interval = bootstrap_ci(difference, statistic=np.mean, n_resamples=10_000, rng=0)
    low, high = interval.low, interval.high
    print(
        f"{args.task} validation ({len(contexts)} networks, n = {n}): with the distance "
        f"prior {with_prior.mean():.3f}, every pair alike (p = {mean_probability:.3f}) "
        f"{without.mean():.3f}; paired {difference.mean():+.3f} [{low:+.3f}, {high:+.3f}]"
    )


if __name__ == "__main__":
    main()
