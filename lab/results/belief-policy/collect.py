"""DAgger's data: episodes on freshly generated training networks (never a suite set),
each step labelled with identify-and-plan's action on the same observations.

    python lab/results/belief-policy/collect.py OUT.npz --n 16 --episodes 200 \
        [--first 0] [--policy POLICY.pt --expert-share 0.0]

The behaviour is the expert itself or (``--policy``, a belief policy's weights file) the
belief policy, taking the expert's action instead with probability ``--expert-share`` at
each step (DAgger's beta). Identify-and-plan reads every observation, the actions taken
included, so its label is what it would do in the state the behaviour reached. OUT keeps
what the belief and the policy read (potentials, last actions, legal actions, pattern,
target) beside the labels, so that features can be computed again by replay
(``train.py``). Written once at the end (atomically: a temporary file, then a rename).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

NETWORK_SEED = 7_001
"""The training networks' stream is make_splits(seed=NETWORK_SEED + n); the suite's sets
use seeds 0-2."""


def training_networks(n: int, count: int):
    from spikectl import make_splits

    return make_splits(count, 1, n, 60, seed=NETWORK_SEED + n)[0]


def collect(n: int, episodes: int, first: int, policy: Path | None, expert_share: float,
            seed: int) -> dict[str, np.ndarray]:  # fmt: skip
    from spikectl import NeuronControlEnv, load_controller

    contexts = training_networks(n, first + episodes)
    env = NeuronControlEnv(contexts=contexts)
    expert = load_controller("identify-and-plan", env=env)
    actor = None if policy is None else load_controller(policy, env=env)
    rng = np.random.default_rng([seed, n, first])
    voltage, last, mask, steps, labels, taken, pattern, target, returns = ([] for _ in range(9))
    started = time.process_time()
    for index in range(first, first + episodes):
        observation, info = env.reset(seed=index, options={"context": index})
        expert.reset()
        if actor is not None:
            actor.reset()
        done, total = False, 0.0
        pattern.append(np.asarray(observation["pattern"], dtype=bool))
        target.append(int(observation["target"]))
        while not done:
            voltage.append(np.asarray(observation["voltage"], dtype=np.float64))
            last.append(int(observation["last_action"]))
            mask.append(np.asarray(info["action_mask"], dtype=bool))
            steps.append(int(observation["step"]))
            label = expert.act(observation, info)
            action = label
            if actor is not None:
                chosen = actor.act(observation, info)
                action = label if rng.random() < expert_share else chosen
            labels.append(label)
            taken.append(action)
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        if (index - first + 1) % 20 == 0:
            print(f"{index - first + 1} episodes, mean return {np.mean(returns):.4f}, "
                  f"{time.process_time() - started:.0f} CPU s", flush=True)  # fmt: skip
    return {
        "n": np.array(n), "context": np.arange(first, first + episodes),
        "voltage": np.stack(voltage).reshape(episodes, -1, n),
        "last_action": np.array(last).reshape(episodes, -1),
        "mask": np.stack(mask).reshape(episodes, -1, n + 1),
        "step": np.array(steps).reshape(episodes, -1),
        "label": np.array(labels).reshape(episodes, -1),
        "taken": np.array(taken).reshape(episodes, -1),
        "pattern": np.stack(pattern), "target": np.array(target), "return": np.array(returns),
        "cpu_seconds": np.array(time.process_time() - started),
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--n", type=int, default=16)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--first", type=int, default=0, help="first training network")
    parser.add_argument("--policy", type=Path, default=None)
    parser.add_argument("--expert-share", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=0)
    arguments = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    data = collect(arguments.n, arguments.episodes, arguments.first, arguments.policy,
                   arguments.expert_share, arguments.seed)  # fmt: skip
    partial = arguments.out.with_suffix(".partial.npz")
    np.savez_compressed(partial, **data)
    os.replace(partial, arguments.out)
    print(f"wrote {arguments.out}: mean return {data['return'].mean():.4f}, "
          f"{float(data['cpu_seconds']):.0f} CPU s")  # fmt: skip


if __name__ == "__main__":
    main()
