"""Why identify-and-plan loses to the oracle: measured on the validation networks.

    python docs/results/baselines/diagnose_identify.py [--n-neurons 8] [--size 100]

Plays identify-and-plan on the validation set of make_splits(100, 100, seed=0,
n_val=100) (never the test set) and the same receding-horizon loop given the true
weights (so only identification differs), then splits identify-and-plan's loss
(1 - return) into missed wanted spikes and unwanted spikes by episode step.
"""

import argparse
import time
from contextlib import contextmanager

import numpy as np

import spikectl.planning.policy as policy_module
from spikectl import IdentifyAndPlan, make_splits
from spikectl.envs.env_support import step_rewards
from spikectl.envs.rollout import evaluate_policy

STEP_BINS = (0, 5, 10, 20, 30, 60)


class _TrueWeights:
    """Stands in for ConnectivityEstimate: every weight known and right."""

    def __init__(self, weights: np.ndarray) -> None:
        self._weights = weights.astype(np.int8)

    def add(self, *evidence) -> None:
        pass

    def weights(self, known_sd: float) -> tuple[np.ndarray, np.ndarray]:
        return self._weights, np.ones(self._weights.shape, dtype=bool)

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        return self._weights.astype(np.float64), np.zeros(self._weights.shape)

    def excitation_probability(self, target: int, known_sd: float) -> np.ndarray:
        return (self._weights[:, target] > 0).astype(float)


@contextmanager
def _told_the_weights(contexts):
    """Each new estimate (one per episode, in context order) is the true weights."""
    queue = iter([context.weights for context in contexts])
    original = policy_module.ConnectivityEstimate
    policy_module.ConnectivityEstimate = lambda n, sd: _TrueWeights(next(queue))
    try:
        yield
    finally:
        policy_module.ConnectivityEstimate = original


def _play(contexts, policy):
    started = time.process_time()
    episodes = evaluate_policy(contexts, policy.vector_policy(len(contexts)))
    return episodes, (time.process_time() - started) / len(contexts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-neurons", type=int, default=8)
    parser.add_argument("--size", type=int, default=100, help="validation networks to play")
    args = parser.parse_args()
    _, _, validation = make_splits(100, 100, args.n_neurons, seed=0, n_val=100)
    contexts = validation[: args.size]
    size = len(contexts)
    identify, seconds = _play(contexts, IdentifyAndPlan())
    print(
        f"identify-and-plan:           {identify.returns.mean():.3f} "
        f"+- {identify.returns.std(ddof=1):.3f}  ({seconds:.3f} CPU s per episode)"
    )
    with _told_the_weights(contexts):
        told, seconds = _play(contexts, IdentifyAndPlan())
    print(
        f"same loop, told the weights: {told.returns.mean():.3f} "
        f"+- {told.returns.std(ddof=1):.3f}  ({seconds:.3f} CPU s per episode)"
    )
    patterns = np.stack([context.pattern for context in contexts])  # [S, N]
    targets = np.array([context.target for context in contexts])
    if_spike, if_silent = step_rewards(patterns)
    spikes = identify.spikes[np.arange(size), :, targets]  # [S, N]
    missed = np.where(patterns & ~spikes, if_spike, 0.0)
    unwanted = np.where(~patterns & spikes, if_silent, 0.0)
    print("loss of identify-and-plan by step (mean over networks):")
    print(f"{'steps':<10}{'missed spikes':>15}{'unwanted spikes':>17}{'wanted spikes':>15}")
    for low, high in zip(STEP_BINS[:-1], STEP_BINS[1:], strict=True):
        print(
            f"{low:>2}-{high - 1:<7}{missed[:, low:high].sum() / size:>15.4f}"
            f"{unwanted[:, low:high].sum() / size:>17.4f}"
            f"{patterns[:, low:high].sum() / size:>15.2f}"
        )
    print(f"{'all':<10}{missed.sum() / size:>15.4f}{unwanted.sum() / size:>17.4f}")
    few = patterns.sum(axis=1) <= 2
    print(
        f"networks whose pattern has <= 2 spikes: {few.sum()}, identify-and-plan "
        f"{identify.returns[few].mean():.3f} on them, {identify.returns[~few].mean():.3f} "
        "on the others"
    )


if __name__ == "__main__":
    main()
