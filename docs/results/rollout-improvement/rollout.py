"""Rollout policy improvement over identify-and-plan (issue 43's untried Bayes-adaptive
look-ahead): where the named controller would probe, each candidate action (its probe,
the next-likeliest probes, do nothing) is valued by playing the controller itself, from
this step on, on K networks drawn from its estimate (the same K for every candidate:
common random numbers). The controller in the rollouts keeps identifying as it would,
so the value of what a probe teaches is counted, not assumed. Tasks with the paper's
deterministic, fully observed dynamics only (`paper`, `n16`, `n32`): there the tracked
state is the true one and a drawn network is all that is uncertain.

    python docs/results/rollout-improvement/rollout.py TASK SPLIT N|FIRST:LAST K H C [MARGIN] [--base]

(a research script: it changes nothing in the library).
"""

from __future__ import annotations

import copy
import sys
import time

import numpy as np

from spikectl.envs.env_support import step_rewards
from spikectl.experiments import suite
from spikectl.neuron.simulator import DO_NOTHING, advance
from spikectl.planning.policy import IdentifyAndPlan, environment_settings


class RolloutImprovement(IdentifyAndPlan):
    """The named controller; where it probes, the action of highest mean return over
    ``networks`` drawn networks, each played ``horizon`` steps on by the controller
    itself, among ``candidates`` probes and do nothing."""

    def __init__(self, *args, networks: int = 8, horizon: int = 20, candidates: int = 3,
                 margin: float = 0.0, **settings) -> None:  # fmt: skip
        super().__init__(*args, **settings)
        self.networks, self.horizon, self.candidates = networks, horizon, candidates
        self.margin = margin
        self.in_rollout = False
        self.counts = {
            "decisions": 0,
            "changed": 0,
            "do nothing": 0,
            "other probe": 0,
        }  # shared with the spawned copies

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        before = self.probes + self.gambles
        action = super().act(observation, info)
        if self.in_rollout or self.probes + self.gambles == before:
            return action
        self.counts["decisions"] += 1
        step, target = int(observation["step"]), int(observation["target"])
        pattern = np.asarray(observation["pattern"], dtype=bool)
        mask = np.asarray(info["action_mask"], dtype=bool)
        weights, known = self._planning_weights()
        candidates = self._candidates(action, known, target, mask)
        if len(candidates) < 2:
            return action
        rng = np.random.default_rng([self.seed, self._episodes, step])
        n = weights.shape[0]
        drawn = self.estimate.sample(
            self.known_sd, rng.random((self.networks, n, n)), rng.random((self.networks, n))
        )
        values = [self._value(c, drawn, pattern, target, info, step) for c in candidates]
        # The probe unless another candidate is better by more than the margin.
        values = np.array(values) - self.margin * (np.arange(len(values)) > 0)
        best = candidates[int(np.argmax(values))]  # the first (the probe) on ties
        if best != action:
            self.counts["do nothing" if best == DO_NOTHING else "other probe"] += 1
        if best != action:
            self.counts["changed"] += 1
            self._predict(weights, best)
        return best

    def _candidates(self, action, known, target, mask) -> list[int]:
        ready = self._ready() & ~known.all(axis=1) & mask[1:]
        score = self.estimate.excitation_probability(target, self.known_sd)
        score = score + 1e-3 * (~known).sum(axis=1)
        score[~ready] = -np.inf
        order = [int(i) for i in np.argsort(-score, kind="stable") if np.isfinite(score[i])]
        probes = [action] + [i for i in order if i != action][: self.candidates - 1]
        return probes + [DO_NOTHING] if action != DO_NOTHING else probes

    def _value(self, first, drawn, pattern, target, info, step) -> float:
        """Mean return of steps step .. step + horizon - 1 over the drawn networks,
        ``first`` played now and the controller after."""
        reward_if_spike, reward_if_silent = step_rewards(pattern)
        end = min(step + self.horizon, pattern.shape[0])
        total = 0.0
        for network in drawn:
            clone = copy.deepcopy(self)
            clone.in_rollout = True
            weights = np.ascontiguousarray(network[None])
            state = self._tracker.state.copy()
            n = network.shape[0]
            voltage, spikes = np.empty((1, 1, n)), np.empty((1, 1, n), dtype=bool)
            clone._predict(clone._planning_weights()[0], first)
            action = first
            for t in range(step, end):
                advance(state, weights, np.array([[action]], dtype=np.int64), self.params,
                        voltage, spikes)  # fmt: skip
                total += reward_if_spike[t] if spikes[0, 0, target] else reward_if_silent[t]
                if t + 1 == end:
                    break
                observation = {"voltage": voltage[0, 0].astype(np.float32), "target": target,
                               "pattern": pattern, "step": t + 1, "last_action": action}  # fmt: skip
                action = clone.act(observation, info)
        return total / len(drawn)


def main() -> None:
    task, split, part = sys.argv[1], sys.argv[2], sys.argv[3]
    first, last = (int(v) for v in part.split(":")) if ":" in part else (0, int(part))
    size = last - first
    networks, horizon, candidates = (int(v) for v in sys.argv[4:7])
    margin = float(sys.argv[7]) if len(sys.argv) > 7 and not sys.argv[7].startswith("--") else 0.0
    base = "--base" in sys.argv
    contexts = suite.load_split(task, split)[first:last]
    settings = environment_settings(suite.task(task).extensions, contexts.n_observed)
    if base:
        controller = IdentifyAndPlan(contexts.params, **settings)
    else:
        controller = RolloutImprovement(contexts.params, networks=networks, horizon=horizon,
                                        candidates=candidates, margin=margin, **settings)  # fmt: skip
    from spikectl.envs.rollout import evaluate_policy

    started = time.process_time()
    episodes = evaluate_policy(contexts, controller, extensions=suite.task(task).extensions,
                               seed=suite.suite_version(1).env_seed)  # fmt: skip
    cpu = time.process_time() - started
    print(f"{task} {split} {part} base={base} K={networks} H={horizon} C={candidates} m={margin} "
          f"mean={episodes.returns.mean():.4f} cpu_s/episode={cpu / size:.2f} "
          f"{getattr(controller, 'counts', '')}")  # fmt: skip
    for r in episodes.returns:
        print(f"{r:.6f}")


if __name__ == "__main__":
    main()
