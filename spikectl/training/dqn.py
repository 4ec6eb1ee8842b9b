"""Recurrent double Q-learning over whole episodes (SPEC section 5, paper Appendix D).

``train(config, run_dir)`` runs a whole training job and returns its metrics. One
round: collect ``num_envs`` episodes at once through the vector environment with an
epsilon-greedy policy on the online network's step forward, store them in the episodic
buffer, then make ``updates_per_round`` gradient updates, each on ``batch_size`` whole
episodes sampled uniformly. After every update the target network moves by a soft
update. Every ``eval_every_episodes`` the greedy policy is scored on every training and
every test context; every ``checkpoint_every_episodes`` the whole state is saved so
that ``train(..., resume=True)`` continues bit-identically.
"""

from __future__ import annotations

import copy
import math
import time
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from spikectl.agents import make_agent, masked_q
from spikectl.agents.blocks import observation_batch
from spikectl.rollout import (
    EpisodeBatch,
    do_nothing_policy,
    evaluate_policy,
    make_random_policy,
    run_episodes,
)
from spikectl.training.checkpoint import (
    RunDirError,
    TrainingState,
    load_checkpoint,
    locked_run,
    prepare_run_dir,
    save_checkpoint,
    write_metrics,
)
from spikectl.training.config import TrainConfig
from spikectl.training.contexts import load_or_make_contexts
from spikectl.training.replay import EpisodeBatchArrays, EpisodeReplay
from spikectl.vector_env import NeuronControlVectorEnv

METRIC_FIELDS = (
    "episode", "env_steps", "updates", "epsilon", "train_return", "test_return", "loss",
    "wall_time_s",
)  # fmt: skip


class EpsilonGreedyPolicy:
    """Acts with the online network's step forward, carrying one hidden state per episode.

    With probability epsilon (per step and episode) a uniformly random legal action
    replaces the greedy one. A new instance starts every batch of episodes.
    """

    def __init__(
        self, network: torch.nn.Module, epsilon: float, rng: np.random.Generator, device: str
    ) -> None:
        self.network = network
        self.epsilon = epsilon
        self.rng = rng
        self.device = device
        self.state = None

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        obs = observation_batch(observations, self.device)
        q_values, self.state = self.network.step(obs, self.state)  # [S, n + 1]
        legal = torch.as_tensor(action_mask, device=q_values.device)
        greedy = masked_q(q_values, legal).argmax(dim=1).cpu().numpy() - 1  # [S]
        if self.epsilon <= 0:
            return greedy
        explore = self.rng.random(greedy.shape[0]) < self.epsilon
        scores = self.rng.random(action_mask.shape)  # [S, n + 1]
        scores[~action_mask] = -1.0
        random_actions = scores.argmax(axis=1) - 1
        return np.where(explore, random_actions, greedy)


def sequence_observations(batch: EpisodeBatchArrays, device: str) -> dict[str, torch.Tensor]:
    """Stored episodes → the networks' sequence input, observations 0..N (N + 1 steps)."""
    size, length = batch.actions.shape
    voltage = torch.as_tensor(batch.voltage, device=device)  # [B, N+1, n]
    actions = torch.as_tensor(batch.actions, device=device)  # [B, N]
    no_action = torch.full((size, 1), -1, dtype=torch.long, device=device)
    return {
        "voltage": voltage,
        "last_action": torch.cat([no_action, actions], dim=1),  # [B, N+1]
        "step": torch.arange(length + 1, device=device).expand(size, -1),  # [B, N+1]
        "target": torch.as_tensor(batch.targets, device=device)[:, None].expand(-1, length + 1),
        "pattern": torch.as_tensor(batch.patterns, device=device, dtype=torch.float32)[
            :, None
        ].expand(-1, length + 1, -1),  # [B, N+1, N]
    }


def td_loss(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    config: TrainConfig,
) -> torch.Tensor:
    """Double-Q TD loss over every step of the sampled episodes."""
    device = config.device
    obs_seq = sequence_observations(batch, device)
    actions = torch.as_tensor(batch.actions, device=device)  # [B, N]
    rewards = torch.as_tensor(batch.rewards, device=device)  # [B, N]
    legal = torch.as_tensor(batch.action_masks, device=device)[:, None]  # [B, 1, n+1]
    # One online forward serves both the taken-action values and the double-Q argmax.
    q_values, _ = online(obs_seq)  # [B, N+1, n+1]
    q_taken = q_values[:, :-1].gather(2, (actions + 1)[..., None]).squeeze(2)  # [B, N]
    with torch.no_grad():
        # Double Q-learning: the online network picks the next action, the target
        # network evaluates it; illegal actions are masked in the choice.
        next_actions = masked_q(q_values[:, 1:].detach(), legal).argmax(dim=2)  # [B, N]
        target_q_values, _ = target(obs_seq)  # [B, N+1, n+1]
        next_q = target_q_values[:, 1:].gather(2, next_actions[..., None]).squeeze(2)  # [B, N]
        not_done = torch.ones_like(rewards)
        not_done[:, -1] = 0.0  # the episode terminates after step N-1
        td_target = rewards + config.gamma * not_done * next_q
    if config.loss == "huber":
        return F.smooth_l1_loss(q_taken, td_target)
    return F.mse_loss(q_taken, td_target)


@torch.no_grad()
def soft_update(target: torch.nn.Module, online: torch.nn.Module, tau: float) -> None:
    """target <- tau * online + (1 - tau) * target."""
    for target_param, online_param in zip(target.parameters(), online.parameters(), strict=True):
        target_param.lerp_(online_param, tau)


def greedy_returns(network: torch.nn.Module, env: NeuronControlVectorEnv, device: str) -> float:
    """Mean greedy return over every context of the environment's set (one batch)."""
    network.eval()
    policy = EpsilonGreedyPolicy(network, 0.0, np.random.default_rng(0), device)
    episodes = run_episodes(env, np.arange(env.num_envs), policy)
    network.train()
    return float(episodes.returns.mean())


def build_networks(config: TrainConfig) -> tuple[torch.nn.Module, torch.nn.Module]:
    """Online and target networks, initialised from ``config.seed`` without touching
    Torch's global generator."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        online = make_agent(config.arch, config.n_neurons, config.episode_length, config.sizes)
    online.to(config.device)
    target = copy.deepcopy(online)
    target.requires_grad_(False)
    return online, target


@locked_run
def train(config: TrainConfig, run_dir: str | Path, resume: bool = False) -> list[dict]:
    """Train an agent; returns the metrics rows (also in ``run_dir/metrics.csv``).

    ``resume=True`` continues the run saved in ``run_dir`` from its last checkpoint
    (from step 0 if it stopped before its first). A loss that turns NaN or infinite
    stops the run with a RunDirError before anything more is written; a run that ends
    without a single gradient update warns (RuntimeWarning).
    """
    run_dir = Path(run_dir)
    resume = prepare_run_dir(config, run_dir, resume)
    if config.torch_threads:
        torch.set_num_threads(config.torch_threads)
    train_set, test_set = load_or_make_contexts(config, run_dir)
    online, target = build_networks(config)
    optimizer = torch.optim.Adam(online.parameters(), lr=config.learning_rate)
    replay = EpisodeReplay(config.buffer_size, config.n_neurons, config.episode_length)
    state = TrainingState(rng=np.random.default_rng(np.random.SeedSequence(config.seed)))
    if resume:
        state = load_checkpoint(run_dir, config, online, target, optimizer, replay)
    else:
        state.baselines = {
            name: {
                split: float(evaluate_policy(contexts, policy).returns.mean())
                for split, contexts in (("train", train_set), ("test", test_set))
            }
            for name, policy in (
                ("do_nothing", do_nothing_policy),
                ("random", make_random_policy(config.seed)),
            )
        }

    collect_env = NeuronControlVectorEnv(config.num_envs, contexts=train_set)
    eval_envs = {
        "train": NeuronControlVectorEnv(len(train_set), contexts=train_set),
        "test": NeuronControlVectorEnv(len(test_set), contexts=test_set),
    }
    targets = np.array([c.target for c in train_set], dtype=np.int64)
    patterns = np.stack([c.pattern for c in train_set]).astype(np.int8)
    logger = _Logger(run_dir, config, state)
    started = time.perf_counter() - state.wall_time_s

    def evaluate() -> None:
        state.wall_time_s = time.perf_counter() - started
        row = {
            "episode": state.episodes,
            "env_steps": state.episodes * config.episode_length,
            "updates": state.updates,
            "epsilon": config.epsilon(state.episodes),
            "train_return": greedy_returns(online, eval_envs["train"], config.device),
            "test_return": greedy_returns(online, eval_envs["test"], config.device),
            "loss": state.loss_sum / state.loss_count if state.loss_count else math.nan,
            "wall_time_s": state.wall_time_s,
        }
        state.loss_sum, state.loss_count = 0.0, 0
        state.metrics.append(row)
        write_metrics(run_dir, state.metrics, METRIC_FIELDS)
        logger.log(row)

    if not state.metrics:
        evaluate()
    while state.episodes < config.total_episodes:
        epsilon = config.epsilon(state.episodes)
        contexts = state.rng.integers(len(train_set), size=config.num_envs)
        policy = EpsilonGreedyPolicy(online, epsilon, state.rng, config.device)
        episodes: EpisodeBatch = run_episodes(collect_env, contexts, policy)
        replay.add(
            episodes.voltage, episodes.actions, episodes.rewards, targets[contexts],
            patterns[contexts], episodes.action_mask,
        )  # fmt: skip
        before = state.episodes
        state.episodes += config.num_envs
        logger.progress(config.num_envs, epsilon, float(episodes.returns.mean()))
        if len(replay) >= max(config.learning_starts, 1):
            for _ in range(config.updates_per_round):
                loss = td_loss(online, target, replay.sample(config.batch_size, state.rng), config)
                if not torch.isfinite(loss):
                    raise RunDirError(
                        f"the TD loss became {loss.item()} at update {state.updates + 1} "
                        f"(episode {state.episodes}): training diverged; the last good "
                        f"checkpoint in {run_dir} is kept (lower --learning-rate?)"
                    )
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                if config.max_grad_norm > 0:
                    torch.nn.utils.clip_grad_norm_(online.parameters(), config.max_grad_norm)
                optimizer.step()
                soft_update(target, online, config.tau)
                state.updates += 1
                state.loss_sum += loss.item()
                state.loss_count += 1
        finished = state.episodes >= config.total_episodes
        if finished or _crossed(before, state.episodes, config.eval_every_episodes):
            evaluate()
        if finished or _crossed(before, state.episodes, config.checkpoint_every_episodes):
            state.wall_time_s = time.perf_counter() - started
            save_checkpoint(run_dir, config, state, online, target, optimizer, replay)
    logger.finish(online, state)
    if state.updates == 0:
        warnings.warn(
            f"the run in {run_dir} made no gradient update (learning_starts="
            f"{config.learning_starts}, updates_per_round={config.updates_per_round}, "
            f"{config.total_episodes} episodes): model.pt is the untrained initial network",
            RuntimeWarning,
            stacklevel=2,
        )
    return state.metrics


def _crossed(before: int, after: int, every: int) -> bool:
    return after // every > before // every


class _Logger:
    """Progress bar and TensorBoard, both optional extras of a run (never its record)."""

    def __init__(self, run_dir: Path, config: TrainConfig, state: TrainingState) -> None:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm.auto import tqdm

        self.run_dir = run_dir
        # purge_step drops events a killed run logged after its last checkpoint.
        self.writer = SummaryWriter(str(run_dir / "tensorboard"), purge_step=state.episodes)
        self.bar = tqdm(
            total=config.total_episodes, initial=state.episodes, unit="ep",
            disable=not config.progress, dynamic_ncols=True, desc=config.arch, mininterval=1.0,
        )  # fmt: skip
        self.last = {}

    def progress(self, episodes: int, epsilon: float, collect_return: float) -> None:
        self.bar.update(episodes)
        # refresh=False: the bar redraws at most every mininterval, not on every round.
        self.bar.set_postfix(
            eps=f"{epsilon:.2f}", collect=f"{collect_return:.3f}", **self.last, refresh=False
        )

    def log(self, row: dict) -> None:
        for key in ("train_return", "test_return", "loss", "epsilon"):
            if not math.isnan(row[key]):
                self.writer.add_scalar(key, row[key], row["episode"])
        self.writer.flush()
        self.last = {"train": f"{row['train_return']:.3f}", "test": f"{row['test_return']:.3f}"}

    def finish(self, online: torch.nn.Module, state: TrainingState) -> None:
        from spikectl.training.checkpoint import save_model

        self.bar.close()
        self.writer.close()
        save_model(self.run_dir, online)
