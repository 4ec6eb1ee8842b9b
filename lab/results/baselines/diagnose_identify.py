"""Why identify-and-plan loses to the oracle: measured on the validation networks.

    python lab/results/baselines/diagnose_identify.py [--n-neurons 8] [--size 100]
        [--skip-first-action]

Plays identify-and-plan on the validation set of make_splits(100, 100, seed=0,
n_val=100) (never the test set) and the same receding-horizon loop given the true
weights (so only identification differs), then splits identify-and-plan's loss
(1 - return) into missed wanted spikes and unwanted spikes by episode step. Then it
plays the loop told only the target's column of G (its inputs), from step k on, and
the loop with its first action forced to each legal action (the best in hindsight
bounds what any choice of the first action could gain).
"""

import argparse
import time
from contextlib import contextmanager

import numpy as np

import spikectl.planning.policy as policy_module
from spikectl import IdentifyAndPlan, make_splits
from spikectl.envs.env_support import step_rewards
from spikectl.envs.rollout import evaluate_policy
from spikectl.planning.identify import KnownConnectivity

STEP_BINS = (0, 5, 10, 20, 30, 60)


class _ToldTheTargetColumn(policy_module.ConnectivityEstimate):
    """The estimate, but the target's column is the truth once ``step >= told_from``."""

    def __init__(self, n, residual_sd, weights, target, told_from):
        super().__init__(n, residual_sd)
        self._true, self._target, self._told_from = weights, target, told_from
        self._step = 0

    @property
    def step(self) -> int:
        return self._step

    @step.setter
    def step(self, step: int) -> None:
        # The policy re-reads its planning weights only when the estimate's version
        # changes: being told the column is a change.
        if self._step < self._told_from <= step:
            self.version += 1
        self._step = step

    def _told(self) -> bool:
        return self._step >= self._told_from

    def weights(self, known_sd):
        signs, known = super().weights(known_sd)
        if self._told():
            signs, known = signs.copy(), known.copy()
            signs[:, self._target] = self._true[:, self._target]
            known[:, self._target] = True
        return signs, known

    def posterior(self):
        mean, sd = super().posterior()
        if self._told():
            mean, sd = mean.copy(), sd.copy()
            mean[:, self._target] = self._true[:, self._target]
            sd[:, self._target] = 0.0
        return mean, sd


@contextmanager
def _patched_policy(contexts, told_from=None, first_action=None):
    """Identify-and-plan told the target's column from step ``told_from`` on, and/or
    with its first action forced to ``first_action`` (where legal)."""
    queue = iter(contexts)
    original_estimate, original_act = policy_module.ConnectivityEstimate, IdentifyAndPlan.act

    def estimate(n, residual_sd):
        context = next(queue)
        return _ToldTheTargetColumn(n, residual_sd, context.weights, context.target,
                                    np.inf if told_from is None else told_from)  # fmt: skip

    def act(self, observation, info):
        step = int(observation["step"])
        if self.estimate is not None:
            self.estimate.step = step
        action = original_act(self, observation, info)
        self.estimate.step = step
        if step == 0 and first_action is not None and info["action_mask"][first_action + 1]:
            action = first_action
            self._predict(self._planning_weights()[0], action)
        return action

    policy_module.ConnectivityEstimate = estimate
    IdentifyAndPlan.act = act
    try:
        yield
    finally:
        policy_module.ConnectivityEstimate = original_estimate
        IdentifyAndPlan.act = original_act


@contextmanager
def _told_the_weights(contexts):
    """Each new estimate (one per episode, in context order) is the true weights."""
    queue = iter([context.weights for context in contexts])
    original = policy_module.ConnectivityEstimate
    policy_module.ConnectivityEstimate = lambda n, sd: KnownConnectivity(next(queue))
    try:
        yield
    finally:
        policy_module.ConnectivityEstimate = original


def _play(contexts, policy):
    started = time.process_time()
    episodes = evaluate_policy(contexts, policy)
    return episodes, (time.process_time() - started) / len(contexts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-neurons", type=int, default=8)
    parser.add_argument("--size", type=int, default=100, help="validation networks to play")
    parser.add_argument(
        "--skip-first-action", action="store_true", help="skip the n + 1 forced-first-action runs"
    )
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
    print("the loop told only the target's column (its inputs) from step k on:")
    for told_from in (0, 1, 5, 10):
        with _patched_policy(contexts, told_from=told_from):
            told, _ = _play(contexts, IdentifyAndPlan())
        print(f"  k = {told_from:>2}: {told.returns.mean():.3f}")
    if args.skip_first_action:
        return
    forced = np.full((args.n_neurons + 1, size), np.nan)  # [do nothing + n, S]
    for first_action in range(-1, args.n_neurons):
        with _patched_policy(contexts, first_action=first_action):
            episodes, _ = _play(contexts, IdentifyAndPlan())
        legal = episodes.action_mask[:, first_action + 1]
        forced[first_action + 1] = np.where(legal, episodes.returns, np.nan)
    print(
        f"first action forced: best in hindsight {np.nanmax(forced, axis=0).mean():.3f}, "
        f"mean over legal first actions {np.nanmean(forced, axis=0).mean():.3f}, "
        f"do nothing {forced[0].mean():.3f}"
    )


if __name__ == "__main__":
    main()
