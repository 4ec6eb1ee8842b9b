"""The look-ahead at step 0 over networks drawn from the estimate (a prototype, validation
only): each legal first action valued by the return of identify-and-plan played on
K drawn networks after it (weighted by what the target and the pattern's second step
say, qmdp.context_likelihood), the planner's own action on ties.

    python lab/results/first-action/rollout_validation.py K STEPS validation OUT.txt
"""

import copy
import json
import sys

import numpy as np

from spikectl.envs.env_support import step_rewards
from spikectl.experiments import suite
from spikectl.neuron.simulator import DO_NOTHING, advance
from spikectl.planning.policy import IdentifyAndPlan
from spikectl.planning.qmdp import context_likelihood


class Rollout(IdentifyAndPlan):
    def __init__(self, *a, rollout_networks=16, rollout_steps=1, rollout_seed=0, **k):
        super().__init__(*a, **k)
        self.rollout_networks, self.rollout_steps = rollout_networks, rollout_steps
        self.rollout_seed = rollout_seed
        self.shadow = False

    def spawn(self, index):
        c = copy.deepcopy(self)
        c.seed = self.seed + index
        c.reset()
        return c

    def act(self, observation, info):
        step = int(observation["step"])
        base = super().act(observation, info)
        if self.shadow or step >= self.rollout_steps or not self.rollout_networks:
            return base
        mask = np.asarray(info["action_mask"], dtype=bool)
        pattern = np.asarray(observation["pattern"], dtype=bool)
        target = int(observation["target"])
        n = mask.shape[0] - 1
        legal = (np.flatnonzero(mask) + DO_NOTHING).astype(np.int64)
        rng = np.random.default_rng([self.rollout_seed, self._episodes, step])
        K = self.rollout_networks
        networks = self.estimate.sample(self.known_sd, rng.random((K, n, n)), rng.random((K, n)))
        w = context_likelihood(networks, target, pattern, legal.shape[0])
        if not w.sum() > 0:
            w = np.ones(K)
        weights, _ = self._planning_weights()
        reward_if_spike, reward_if_silent = step_rewards(pattern)
        values = np.zeros((K, legal.shape[0]))
        for k in range(K):
            if w[k] == 0:
                continue
            net = np.ascontiguousarray(networks[k][None])
            for j, a in enumerate(legal):
                shadow = copy.deepcopy(self)
                shadow.shadow = True
                shadow._predict(weights, int(a))
                state = self._tracker.state.copy()
                v = np.empty((1, 1, n))
                s = np.empty((1, 1, n), dtype=bool)
                act = int(a)
                total = 0.0
                for t in range(step, pattern.shape[0]):
                    if t > step:
                        obs = {
                            "voltage": v[0, 0].astype(np.float32),
                            "target": target,
                            "pattern": pattern,
                            "step": t,
                            "last_action": act,
                        }
                        act = shadow.act(obs, info)
                    advance(state, net, np.array([[act]], dtype=np.int64), self.params, v, s)
                    total += reward_if_spike[t] if s[0, 0, target] else reward_if_silent[t]
                values[k, j] = total
        q = (w / w.sum()) @ values
        best = q.max()
        base_j = int(np.flatnonzero(legal == base)[0])
        choice = base if q[base_j] >= best - 1e-12 else int(legal[np.argmax(q)])
        self._predict(weights, choice)
        return choice


def main():
    K, S, split = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    out = sys.argv[4]
    returns, cpu = suite.play("paper", split, Rollout(rollout_networks=K, rollout_steps=S))
    np.savetxt(out, returns)
    print(json.dumps({"K": K, "S": S, "split": split, "mean": float(returns.mean()), "cpu_s": cpu}))


if __name__ == "__main__":
    main()
