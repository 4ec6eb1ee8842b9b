"""Fine-tune a belief policy by policy gradient (REINFORCE) on freshly generated training
networks, on one thread.

    python lab/results/belief-policy/reinforce.py OUT.pt --start START.pt \
        [--sizes 8 16 32 --updates 200 --batch 32 --group 4 --learning-rate 3e-4 --seed 0]

Each update plays ``--batch`` episodes at one size (the sizes in turn) on training
networks (``collect.training_networks``, a stream no suite set draws from), sampling each
action from the softmax of the policy's scores over the legal actions. The gradient is
REINFORCE's with the reward still to come, less a baseline, scaled by the
advantages' standard deviation, plus an entropy bonus. With ``--group 1`` the baseline
is the batch's mean reward still to come at the same step; with ``--group K`` each
network is played K times and the baseline of an episode is the mean return of the
other K - 1 on the same network (leave-one-out), which removes the networks' own spread
from the gradient.
The belief is not trained (its features do not depend on the policy's weights, so a
batch's features are computed once, while playing). Writes OUT (the belief's and the
policy's weights, as ``spikectl.load_controller`` reads them) and OUT.csv (per update:
the size, the batch's mean return, the entropy, CPU seconds).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.records import write_csv
from spikectl import NeuronControlEnv
from spikectl.agents.amortised_kernel import BeliefKernel
from spikectl.agents.belief_policy import (
    BeliefPolicyController,
    PolicyKernel,
    read_belief_policy,
    save_belief_policy,
)
from spikectl.neuron import DO_NOTHING

_spec = importlib.util.spec_from_file_location("collect", Path(__file__).with_name("collect.py"))
collect = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(collect)

NETWORKS_PER_SIZE = 10_000
"""Training networks drawn at each size: each update takes the next ``batch / group``,
from ``seed * 2 000`` on (modulo this)."""


class Sampling(BeliefPolicyController):
    """The belief policy drawing its action from the softmax of its scores (legal ones),
    keeping each step's features, legal actions and chosen index."""

    def __init__(self, belief, policy, rng: np.random.Generator) -> None:
        super().__init__(belief, policy)
        self.rng = rng
        self.record: list[tuple[np.ndarray, np.ndarray, int]] = []

    def decide(self, pattern, step, mask) -> int:
        features = self.features(pattern, step, mask)
        scores = np.where(mask, self.policy.scores(features), -np.inf)
        chance = np.exp(scores - scores.max())
        chance /= chance.sum()
        index = int(self.rng.choice(chance.shape[0], p=chance))
        self.record.append((features, mask.copy(), index))
        return index + DO_NOTHING


def play_batch(env, controller: Sampling, first: int, batch: int, group: int = 1):
    """(features [B, T, n, D], masks [B, T, n + 1], chosen [B, T], rewards [B, T]): B =
    ``batch`` episodes, ``group`` in a row on each network from ``first`` on."""
    features, masks, chosen, rewards = [], [], [], []
    for index in np.repeat(np.arange(first, first + batch // group), group).tolist():
        controller.record, step_rewards = [], []
        observation, info = env.reset(seed=index, options={"context": index})
        controller.reset()
        done = False
        while not done:
            action = controller.act(observation, info)
            observation, reward, terminated, truncated, info = env.step(action)
            step_rewards.append(float(reward))
            done = terminated or truncated
        f, m, c = zip(*controller.record, strict=True)
        features.append(np.stack(f))
        masks.append(np.stack(m))
        chosen.append(np.array(c))
        rewards.append(np.array(step_rewards))
    return (np.stack(features), np.stack(masks), np.stack(chosen), np.stack(rewards))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--start", type=Path, required=True)
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32])
    parser.add_argument("--updates", type=int, default=200)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--group", type=int, default=1)
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--entropy", type=float, default=1e-3)
    parser.add_argument("--seed", type=int, default=0)
    arguments = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(arguments.seed)
    belief, net = read_belief_policy(arguments.start)
    kernel = BeliefKernel(belief)
    envs = {n: NeuronControlEnv(contexts=collect.training_networks(n, NETWORKS_PER_SIZE))
            for n in arguments.sizes}  # fmt: skip
    optimiser = torch.optim.Adam(net.parameters(), lr=arguments.learning_rate)
    rng = np.random.default_rng(arguments.seed)
    rows, started = [], time.process_time()
    for update in range(arguments.updates):
        n = arguments.sizes[update % len(arguments.sizes)]
        first = ((update // len(arguments.sizes)) * (arguments.batch // arguments.group)
                 + arguments.seed * 2_000) % (NETWORKS_PER_SIZE - arguments.batch)  # fmt: skip
        controller = Sampling(kernel, PolicyKernel(net.eval()), rng)
        features, masks, chosen, rewards = play_batch(envs[n], controller, first,
                                                      arguments.batch, arguments.group)  # fmt: skip
        to_go = np.cumsum(rewards[:, ::-1], axis=1)[:, ::-1]  # [B, T] reward still to come
        if arguments.group == 1:
            advantage = to_go - to_go.mean(axis=0, keepdims=True)
        else:  # leave-one-out on each network's K episodes, the whole return
            returns = rewards.sum(axis=1).reshape(-1, arguments.group)  # [B / K, K]
            others = (returns.sum(axis=1, keepdims=True) - returns) / (arguments.group - 1)
            advantage = np.repeat((returns - others).reshape(-1, 1), rewards.shape[1], axis=1)
        advantage /= advantage.std() + 1e-8
        net.train()
        b, t = chosen.shape
        scores = net(torch.from_numpy(features.reshape(b * t, n, -1)))  # [B T, n + 1]
        scores = scores.masked_fill(~torch.from_numpy(masks.reshape(b * t, n + 1)), -1e9)
        log_chance = torch.log_softmax(scores, dim=-1)
        taken = log_chance.gather(1, torch.from_numpy(chosen.reshape(-1, 1))).squeeze(1)
        entropy = -(log_chance.exp() * log_chance).sum(dim=-1).mean()
        loss = -(taken * torch.from_numpy(advantage.reshape(-1)).float()).mean() \
            - arguments.entropy * entropy  # fmt: skip
        optimiser.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        optimiser.step()
        rows.append({"update": update + 1, "n": n, "mean_return": float(rewards.sum(1).mean()),
                     "entropy": float(entropy.detach()),
                     "cpu_seconds": round(time.process_time() - started, 1)})  # fmt: skip
        if (update + 1) % 10 == 0:
            print(rows[-1], flush=True)
        if (update + 1) % 50 == 0 or update + 1 == arguments.updates:
            save_belief_policy(belief, net.eval(), arguments.out)
            write_csv(arguments.out.with_suffix(".csv"), rows)
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
