"""When and whom identify-and-plan probes: three rules against the named controller.

    python docs/results/probing-rules/probing_rules.py TASK SPLIT SIZE RULE [RULE ...]

RULE is one of
  idle-quiet-Q  also probe where the plan would do nothing and misses no wanted spike,
                if the next Q steps want no spike, the probed neuron's synapse onto the
                target is unknown and the plan does not stimulate it within 5 steps
                (the neuron most likely to excite the target among those);
  imminent-H    probe only where the plan misses a wanted spike within the next H
                steps (the named controller probes where it misses one anywhere ahead);
  dale          rank the probe's candidates with Dale's law: an unknown synapse of a
                neuron whose known synapses are excitatory excites with the topology's
                connection probability, of an inhibitory one never.
Plays the named controller (the settings ``spikectl benchmark identify-and-plan``
plays the task with) and each rule on the first SIZE networks of the task's SPLIT
(never ``test``), and prints each rule's mean return, the unwanted spikes' loss and the
paired difference to the named controller network by network (95% interval).
"""

import copy
import sys
import time

import numpy as np

from spikectl.envs.env_support import step_rewards
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning.identify import EXCITATORY_PROBABILITY, ConnectivityEstimate
from spikectl.planning.policy import IdentifyAndPlan, environment_settings

FREE_STEPS = 5  # a neuron releases at most every 5 steps (SPEC section 1)


class IdleQuiet(IdentifyAndPlan):
    quiet = 2

    def act(self, observation, info):
        action = super().act(observation, info)
        step = int(observation["step"])
        if action != DO_NOTHING or step == 0:
            return action
        pattern = np.asarray(observation["pattern"], dtype=bool)
        offset = step - self._plan_start
        if self._misses_from[offset] or pattern[step + 1 : step + 1 + self.quiet].any():
            return action  # the named rule has spoken, or a wanted spike is near
        weights, known = self._planning_weights()
        target = int(observation["target"])
        mask = np.asarray(info["action_mask"], dtype=bool)
        candidates = self._ready() & ~known[:, target] & mask[1:]
        if not candidates.any():
            return action
        score = self.estimate.excitation_probability(target, self.known_sd)
        probe = int(np.argmax(np.where(candidates, score, -np.inf)))
        if probe in self._plan.actions[offset + 1 : offset + 1 + FREE_STEPS]:
            return action
        self._predict(weights, probe)
        return probe

    def spawn(self, index):
        return copy.copy(self)


class Imminent(IdentifyAndPlan):
    within = 1

    def _replan(self, weights, target, mask, pattern, step):
        super()._replan(weights, target, mask, pattern, step)
        wanted = pattern[step : step + self._plan.rewards.shape[0]]
        self._missing = wanted & (self._plan.rewards == 0)

    def _misses_wanted_spikes(self, pattern, offset):
        # The action at ``offset`` reaches the target's reward at ``offset + 1``.
        return bool(self._missing[offset + 1 : offset + 1 + self.within].any())

    def spawn(self, index):
        return copy.copy(self)


class Dale(IdentifyAndPlan):
    def _probe(self, known, target, mask, count=True):
        if not isinstance(self.estimate, ConnectivityEstimate):
            return super()._probe(known, target, mask, count)
        candidates = self._ready() & ~known.all(axis=1) & mask[1:]
        if not candidates.any():
            return DO_NOTHING
        signs, _ = self.estimate.weights(self.known_sd)
        row_sign = np.sign(signs.sum(axis=1))  # [n]: a row's known sign (Dale's law)
        prior = self.estimate.prior_variance[:, target]  # connection probability
        unknown_sign = EXCITATORY_PROBABILITY * prior
        prior_excites = np.where(row_sign > 0, prior, np.where(row_sign < 0, 0.0, unknown_sign))
        score = self.estimate.excitation_probability(target, self.known_sd)
        score = np.where(known[:, target], score, prior_excites)
        score = score + 1e-3 * (~known).sum(axis=1)  # as the named rule's tie-break
        score[~candidates] = -np.inf
        self.probes += count
        return int(np.argmax(score))

    def spawn(self, index):
        return copy.copy(self)


def rule_policy(rule: str, settings: dict) -> IdentifyAndPlan:
    if rule.startswith("idle-quiet-"):
        policy = IdleQuiet(**settings)
        policy.quiet = int(rule.rsplit("-", 1)[1])
    elif rule.startswith("imminent-"):
        policy = Imminent(**settings)
        policy.within = int(rule.rsplit("-", 1)[1])
    elif rule == "dale":
        policy = Dale(**settings)
    else:
        raise SystemExit(f"unknown rule {rule!r}")
    return policy


def main() -> None:
    task, split, size, rules = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
    if split == "test":
        raise SystemExit("choose on train or validation; the test set is played once")
    contexts = suite.load_split(task, split)[:size]
    spec = suite.task(task)
    settings = {"noise_mV": spec.extensions.observation_noise_mV,
                **environment_settings(spec.extensions, spec.n_neurons)}  # fmt: skip
    patterns = np.stack([context.pattern for context in contexts])  # [S, N]
    targets = np.array([context.target for context in contexts])
    _, if_silent = step_rewards(patterns)

    def play(policy):
        started = time.process_time()
        episodes = evaluate_policy(contexts, policy, extensions=spec.extensions,
                                   seed=suite.suite_version(1).env_seed)  # fmt: skip
        spikes = episodes.spikes[np.arange(len(contexts)), :, targets]  # [S, N]
        unwanted = np.where(~patterns & spikes, if_silent, 0.0).sum(axis=1).mean()
        return episodes.returns, unwanted, time.process_time() - started

    named, unwanted, seconds = play(IdentifyAndPlan(**settings))
    print(f"{task} {split} {size} networks; named {named.mean():.4f} "
          f"(unwanted spikes {unwanted:.4f}, {seconds:.0f} CPU s)", flush=True)  # fmt: skip
    for rule in rules:
        returns, unwanted, seconds = play(rule_policy(rule, settings))
        difference = paired_difference_cells(returns - named)
        print(f"  {rule:<14} {returns.mean():.4f} (unwanted spikes {unwanted:.4f}, "
              f"{seconds:.0f} CPU s)  - named {difference}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
