"""lab.planners.column: identify-and-plan's Gaussian posterior of the target's column,
read from the amortised controller's feature rows."""

from __future__ import annotations

import numpy as np

from lab.planners.column import GaussianColumn
from spikectl import NeuronControlEnv, make_splits
from spikectl.agents.amortised_kernel import BeliefFeatureTracker, target_prior
from spikectl.planning import ConnectivityEstimate, IdentifyAndPlan, ObservedState


def test_the_column_is_identify_and_plans_posterior_of_that_column():
    """On random stimulations of generated networks, every step's P(+1) and P(-1) of the
    column equal ConnectivityEstimate.entry_probabilities() of the target's column fed
    the same observations (to the rows' float32), and they move off the prior."""
    contexts = make_splits(3, 3, 16, seed=5)[1]
    env = NeuronControlEnv(contexts=contexts)
    rng = np.random.default_rng(0)
    residual_sd = IdentifyAndPlan().observation.residual_sd  # the named controller's
    moved = 0
    for index in range(len(contexts)):
        observation, info = env.reset(seed=index, options={"context": index})
        n, target = contexts.n_neurons, int(observation["target"])
        tracker = BeliefFeatureTracker(n, target, contexts.params)
        column = GaussianColumn()
        column.reset(target_prior(n, target))
        estimate = ConnectivityEstimate(n, residual_sd)
        state = ObservedState(n, contexts.params, 0.0)
        done = False
        while not done:
            legal = np.flatnonzero(info["action_mask"][1:])
            action = int(rng.choice(legal)) if rng.random() < 0.5 else -1
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            voltage = np.asarray(observation["voltage"], dtype=np.float64)
            probabilities = np.exp(column.step(tracker.row(voltage, action)))
            estimate.add(*state.observe(voltage, action))
            excites, inhibits = estimate.entry_probabilities()
            # The rows are float32: a residual differs from the estimate's by ~1e-7.
            np.testing.assert_allclose(probabilities[:, 1], excites[:, target], atol=1e-6)
            np.testing.assert_allclose(probabilities[:, 2], inhibits[:, target], atol=1e-6)
            np.testing.assert_allclose(probabilities.sum(axis=1), 1.0, atol=3e-9)
        moved += int(np.any(np.abs(probabilities[:, 1] - target_prior(n, target) * 0.8) > 0.1))
    assert moved == len(contexts)
