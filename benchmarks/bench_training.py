"""Trainer cost: gradient-update time against a bare PyTorch loop, and collection rate.

Update: the trainer's update (sample from the replay buffer, build the sequence input,
``td_loss`` with one online and one target forward, backward, gradient clipping, Adam,
soft target update) against a bare loop that runs the same online forward, target
forward, MSE backward and Adam step on tensors prepared in advance. Both at paper size
(Table 2 networks, batch 5 episodes x 60 steps) in the same run, interleaved.

Collection: environment steps per second of epsilon-greedy acting with the online
network's step forward on 64 networks in parallel (the trainer's ``run_episodes``).

Also reports how long one ``paper`` run (1 M steps) would take from these numbers.

    python benchmarks/bench_training.py [--archs tdrqn drqn] [--updates 30]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
import torch.nn.functional as F

from spikectl.agents import ARCHITECTURES
from spikectl.contexts import make_splits
from spikectl.envs.rollout import run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.training.learners.dqn import soft_update, td_loss
from spikectl.training.learners.q_learning import (
    EpsilonGreedyPolicy,
    build_networks,
    sequence_observations,
)
from spikectl.training.presets import PAPER, PRESETS
from spikectl.training.replay import EpisodeReplay


def filled_replay(config, train_set, rng) -> EpisodeReplay:
    """A buffer with 64 random-policy episodes of the training set."""
    online, _ = build_networks(config)
    env = NeuronControlVectorEnv(64, contexts=train_set)
    replay = EpisodeReplay(
        config.learner.buffer_size, config.env.n_neurons, config.env.episode_length
    )
    contexts = rng.integers(len(train_set), size=64)
    episodes = run_episodes(env, contexts, EpsilonGreedyPolicy(online, 1.0, rng, "cpu"))
    targets = np.array([train_set[i].target for i in contexts])
    patterns = np.stack([train_set[i].pattern for i in contexts]).astype(np.int8)
    replay.add(episodes.voltage, episodes.actions, episodes.rewards, targets, patterns,
               episodes.action_mask)  # fmt: skip
    return replay


def time_updates(config, replay, updates: int, rng) -> tuple[float, float]:
    """Median seconds of (trainer update, bare update)."""
    online, target = build_networks(config)
    optimizer = torch.optim.Adam(online.parameters(), lr=config.learner.learning_rate)
    bare_online, bare_target = build_networks(config)
    bare_optimizer = torch.optim.Adam(bare_online.parameters(), lr=config.learner.learning_rate)
    fixed = replay.sample(config.learner.batch_size, rng)
    obs_seq = sequence_observations(fixed, "cpu")
    index = torch.as_tensor(fixed.actions + 1)[..., None]  # [B, N, 1]
    td_target = torch.as_tensor(fixed.rewards)  # any fixed target: the cost is the same

    def trainer_update() -> None:
        batch = replay.sample(config.learner.batch_size, rng)
        loss = td_loss(online, target, batch, config.learner)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(online.parameters(), config.learner.max_grad_norm)
        optimizer.step()
        soft_update(target, online, config.learner.tau)

    def bare_update() -> None:
        q_values, _ = bare_online(obs_seq)
        with torch.no_grad():
            bare_target(obs_seq)
        loss = F.mse_loss(q_values[:, :-1].gather(2, index).squeeze(2), td_target)
        bare_optimizer.zero_grad(set_to_none=True)
        loss.backward()
        bare_optimizer.step()

    trainer_times, bare_times = [], []
    for _ in range(3):
        trainer_update()
        bare_update()
    for _ in range(updates):  # interleaved so both see the same machine load
        start = time.perf_counter()
        trainer_update()
        trainer_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        bare_update()
        bare_times.append(time.perf_counter() - start)
    return float(np.median(trainer_times)), float(np.median(bare_times))


def collection_rate(config, train_set, num_envs: int, episodes: int, rng) -> float:
    """Environment steps per second of epsilon-greedy acting (epsilon 0.5)."""
    online, _ = build_networks(config)
    env = NeuronControlVectorEnv(num_envs, contexts=train_set)
    rates = []
    for repeat in range(episodes + 1):
        contexts = rng.integers(len(train_set), size=num_envs)
        start = time.perf_counter()
        run_episodes(env, contexts, EpsilonGreedyPolicy(online, 0.5, rng, "cpu"))
        if repeat:
            rates.append(num_envs * config.env.episode_length / (time.perf_counter() - start))
    return float(np.median(rates))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--archs", nargs="+", default=list(ARCHITECTURES))
    parser.add_argument("--updates", type=int, default=30)
    parser.add_argument("--episodes", type=int, default=5, help="collection repeats")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--sizes", choices=sorted(PRESETS), default="paper", help="whose network sizes to time"
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(0)
    train_set, _ = make_splits(100, 1)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, {args.sizes} sizes")
    print(
        "| agent | trainer update (ms) | bare loop (ms) | ratio | collection, 64 envs "
        "(steps/s) | one paper run (h) |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for arch in args.archs:
        config = PAPER.with_changes(arch=arch, sizes=PRESETS[args.sizes].agent.sizes)
        replay = filled_replay(config, train_set, rng)
        trainer_s, bare_s = time_updates(config, replay, args.updates, rng)
        rate = collection_rate(config, train_set, 64, args.episodes, rng)
        paper_rate = collection_rate(config, train_set, config.train.num_envs, args.episodes, rng)
        rounds = config.total_episodes // config.train.num_envs
        paper_hours = (
            rounds * config.learner.updates_per_round * trainer_s
            + config.train.total_env_steps / paper_rate
        ) / 3600
        print(f"| {arch} | {trainer_s * 1e3:.1f} | {bare_s * 1e3:.1f} | {trainer_s / bare_s:.2f} "
              f"| {rate:,.0f} | {paper_hours:.1f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
