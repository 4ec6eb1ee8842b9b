"""Recurrent double Q-learning over whole episodes (docs/training.md, paper Appendix D).

``train(config, run_dir)`` runs a whole training job and returns its metrics. One
round: collect ``num_envs`` episodes at once through the vector environment with an
epsilon-greedy policy on the online network's step forward, store them in the episodic
buffer, then make ``updates_per_round`` gradient updates, each on ``batch_size`` whole
episodes sampled uniformly. The TD target is the double-Q target, over ``n_step``
observed rewards (1 in the paper); with ``aux_voltage_weight > 0`` an auxiliary head
predicting every neuron's next voltage adds its loss. After every update the target
network moves by a soft update. Every ``eval_every_episodes`` the greedy policy is
scored on every training, test and validation context; every
``checkpoint_every_episodes`` the whole state is saved so that
``train(..., resume=True)`` continues bit-identically.
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

from spikectl.agents import make_agent, make_voltage_predictor, masked_q
from spikectl.agents.blocks import normalised_voltage, observation_batch
from spikectl.envs.env_support import random_legal_actions
from spikectl.envs.rollout import (
    EpisodeBatch,
    do_nothing_policy,
    evaluate_policy,
    make_random_policy,
    run_episodes,
)
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.training.checkpoint import (
    BEST_MODEL_FILE,
    RunDirError,
    TrainingState,
    forget_best_model_after,
    load_checkpoint,
    locked_run,
    prepare_run_dir,
    save_checkpoint,
    save_model,
    write_metrics,
)
from spikectl.training.config import Experiment
from spikectl.training.contexts import (
    COLLECT_STREAM,
    EVAL_STREAM,
    load_or_make_contexts,
    make_env,
    stream_seed,
)
from spikectl.training.replay import EpisodeBatchArrays, EpisodeReplay

METRIC_FIELDS = (
    "episode", "env_steps", "updates", "epsilon", "train_return", "test_return", "loss",
    "wall_time_s", "val_return", "aux_loss", "cpu_time_s",
)  # fmt: skip


class EpsilonGreedyPolicy:
    """Acts with the online network's step forward, carrying one hidden state per episode.

    With probability epsilon (per step and episode) a random legal action replaces the
    greedy one: uniform over the legal actions (``explore_do_nothing=None``, the paper),
    or "do nothing" with probability ``explore_do_nothing`` and otherwise a uniform legal
    stimulation. A new instance starts every batch of episodes.
    """

    def __init__(
        self,
        network: torch.nn.Module,
        epsilon: float,
        rng: np.random.Generator,
        device: str,
        explore_do_nothing: float | None = None,
    ) -> None:
        self.network = network
        self.epsilon = epsilon
        self.rng = rng
        self.device = device
        self.explore_do_nothing = explore_do_nothing
        self.state = None

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        obs = observation_batch(observations, self.device)
        q_values, self.state = self.network.step(obs, self.state)  # [S, n + 1]
        legal = torch.as_tensor(action_mask, device=q_values.device)
        greedy = masked_q(q_values, legal).argmax(dim=1).cpu().numpy() - 1  # [S]
        if self.epsilon <= 0:
            return greedy
        return explore(greedy, action_mask, self.epsilon, self.rng, self.explore_do_nothing)


def explore(
    greedy: np.ndarray,
    action_mask: np.ndarray,
    epsilon: float,
    rng: np.random.Generator,
    explore_do_nothing: float | None,
) -> np.ndarray:
    """Epsilon-greedy: greedy actions [S] with each replaced, with probability epsilon, by
    a random legal one (the draws every policy of a run makes, in this order)."""
    exploring = rng.random(greedy.shape[0]) < epsilon  # [S]
    if explore_do_nothing is None:
        random_actions = random_legal_actions(action_mask, rng)
    else:
        # A random stimulation, replaced by do nothing with probability explore_do_nothing.
        stimulations = action_mask.copy()
        stimulations[:, 0] = False
        random_actions = random_legal_actions(stimulations, rng)
        nothing = rng.random(greedy.shape[0]) < explore_do_nothing
        random_actions[nothing] = -1
    return np.where(exploring, random_actions, greedy)


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


def n_step_targets(
    rewards: torch.Tensor, bootstrap: torch.Tensor, gamma: float, n_step: int
) -> torch.Tensor:
    """n-step TD targets of every step of whole episodes.

    ``rewards`` [B, N] are r_0 … r_{N-1}; ``bootstrap`` [B, N + 1] is the value of
    observation j (the one before step j), 0 at j = N because the episode terminates
    after step N - 1. For step t:

        td_target_t = Σ_{k<n, t+k<N} γ^k r_{t+k}  +  γ^n · bootstrap[t + n]

    with bootstrap beyond N read as 0. With n = 1 this is r_t + γ · bootstrap[t + 1].
    """
    steps = rewards.shape[1]
    discounts = gamma ** torch.arange(n_step, dtype=rewards.dtype, device=rewards.device)  # [n]
    windows = F.pad(rewards, (0, n_step - 1)).unfold(1, n_step, 1)  # [B, N, n]
    reward_sums = (windows * discounts).sum(dim=2)  # [B, N]
    future = F.pad(bootstrap, (0, n_step - 1))[:, n_step : n_step + steps]  # [B, N]
    return reward_sums + gamma**n_step * future


def training_losses(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    config: Experiment,
    predictor: torch.nn.Module | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The double-Q TD loss over every step of the sampled episodes and, with a
    ``predictor``, the auxiliary next-voltage loss (None without one)."""
    tensors = batch_tensors(batch, config.train.device)
    return losses_on_tensors(online, target, tensors, config, predictor)


def batch_tensors(batch: EpisodeBatchArrays, device: str) -> dict[str, torch.Tensor]:
    """Sampled episodes as the tensors the losses read (``obs_seq`` is a nested dict)."""
    return {
        "obs_seq": sequence_observations(batch, device),
        "actions": torch.as_tensor(batch.actions, device=device),  # [B, N]
        "rewards": torch.as_tensor(batch.rewards, device=device),  # [B, N]
        "legal": torch.as_tensor(batch.action_masks, device=device)[:, None],  # [B, 1, n+1]
    }


def losses_on_tensors(
    online,
    target,
    tensors: dict,
    config: Experiment,
    predictor=None,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """:func:`training_losses` on :func:`batch_tensors`' output; the networks may be
    modules or one seed's view of stacked networks (inside vmap)."""
    obs_seq, actions, rewards, legal = (
        tensors["obs_seq"], tensors["actions"], tensors["rewards"], tensors["legal"]
    )  # fmt: skip
    # One online forward serves the taken-action values, the double-Q argmax and the
    # auxiliary prediction (which reads the encoder's features).
    if predictor is None:
        q_values, _ = online(obs_seq)  # [B, N+1, n+1]
    else:
        features, _ = online.encode(obs_seq)  # [B, N+1, (n,) D]
        q_values = online.q_values(features, obs_seq)  # [B, N+1, n+1]
    q_taken = q_values[:, :-1].gather(2, (actions + 1)[..., None]).squeeze(2)  # [B, N]
    with torch.no_grad():
        # Double Q-learning: the online network picks the action at every observation,
        # the target network evaluates it; illegal actions are masked in the choice.
        best_actions = masked_q(q_values.detach(), legal).argmax(dim=2)  # [B, N+1]
        target_q_values, _ = target(obs_seq)  # [B, N+1, n+1]
        bootstrap = target_q_values.gather(2, best_actions[..., None]).squeeze(2)  # [B, N+1]
        bootstrap[:, -1] = 0.0  # observation N follows the terminal step
        td_target = n_step_targets(
            rewards, bootstrap, config.train.gamma, config.train.n_step
        )  # [B, N]
    if config.train.loss == "huber":
        td = F.smooth_l1_loss(q_taken, td_target)
    else:
        td = F.mse_loss(q_taken, td_target)
    if predictor is None:
        return td, None
    next_voltage = normalised_voltage(
        obs_seq["voltage"][:, 1:], online.v_rest_mV, online.v_threshold_mV
    )  # [B, N, n]
    predicted = predictor(features[:, :-1], actions)  # [B, N, n]
    return td, F.mse_loss(predicted, next_voltage)


def td_loss(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    config: Experiment,
) -> torch.Tensor:
    """Double-Q TD loss over every step of the sampled episodes."""
    return training_losses(online, target, batch, config)[0]


@torch.no_grad()
def soft_update(target: torch.nn.Module, online: torch.nn.Module, tau: float) -> None:
    """target <- tau * online + (1 - tau) * target."""
    for target_param, online_param in zip(target.parameters(), online.parameters(), strict=True):
        target_param.lerp_(online_param, tau)


def greedy_returns(
    network: torch.nn.Module, env: NeuronControlVectorEnv, device: str, seed: int
) -> float:
    """Mean greedy return over every context of the environment's set (one batch); the
    environment's own draws (noise, ...) start from ``seed`` every time."""
    network.eval()
    policy = EpsilonGreedyPolicy(network, 0.0, np.random.default_rng(0), device)
    env.reset(seed=seed)
    episodes = run_episodes(env, np.arange(env.num_envs), policy)
    network.train()
    return float(episodes.returns.mean())


def build_networks(config: Experiment) -> tuple[torch.nn.Module, torch.nn.Module]:
    """Online and target networks, initialised from ``config.train.seed`` without touching
    Torch's global generator."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.train.seed)
        online = make_agent(
            config.agent.arch, config.env.n_observed, config.env.episode_length,
            config.agent.sizes, params=config.env.params,
        )  # fmt: skip
    online.to(config.train.device)
    target = copy.deepcopy(online)
    target.requires_grad_(False)
    return online, target


def build_predictor(config: Experiment, online: torch.nn.Module) -> torch.nn.Module | None:
    """The auxiliary next-voltage head when ``aux_voltage_weight > 0``, seeded from
    ``config.train.seed`` on a stream of its own (the Q-network's initialisation is unchanged)."""
    if config.train.aux_voltage_weight <= 0:
        return None
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(np.random.SeedSequence([config.train.seed, 1]).generate_state(1)[0])
        predictor = make_voltage_predictor(online)
    return predictor.to(config.train.device)


def set_learning_rate(optimizer: torch.optim.Optimizer, learning_rate: float) -> None:
    """Set every parameter group's learning rate (the schedule is a pure function of the
    episode count, so a resumed run needs no scheduler state)."""
    for group in optimizer.param_groups:
        group["lr"] = learning_rate


@locked_run
def train(config: Experiment, run_dir: str | Path, resume: bool = False) -> list[dict]:
    """Train an agent; returns the metrics rows (also in ``run_dir/metrics.csv``).

    ``resume=True`` continues the run saved in ``run_dir`` from its last checkpoint
    (from step 0 if it stopped before its first). A loss that turns NaN or infinite
    stops the run with a RunDirError before anything more is written; a run that ends
    without a single gradient update warns (RuntimeWarning).
    """
    run_dir = Path(run_dir)
    resume = prepare_run_dir(config, run_dir, resume)
    if config.train.torch_threads:
        torch.set_num_threads(config.train.torch_threads)
    train_set, test_set, val_set = load_or_make_contexts(config, run_dir)
    online, target = build_networks(config)
    predictor = build_predictor(config, online)
    trained = list(online.parameters()) + (list(predictor.parameters()) if predictor else [])
    optimizer = torch.optim.Adam(trained, lr=config.train.learning_rate)
    replay = EpisodeReplay(
        config.train.buffer_size, config.env.n_observed, config.env.episode_length
    )
    state = TrainingState(rng=np.random.default_rng(np.random.SeedSequence(config.train.seed)))
    if resume:
        state = load_checkpoint(run_dir, config, online, target, optimizer, replay, predictor)
        forget_best_model_after(run_dir, state.episodes)
    else:
        state.baselines = {
            name: {
                split: float(baseline_episodes(config, contexts, policy).returns.mean())
                for split, contexts in (("train", train_set), ("test", test_set))
            }
            for name, policy in (
                ("do_nothing", do_nothing_policy),
                ("random", make_random_policy(config.train.seed)),
            )
        }

    collect_env = make_env(config, train_set, config.train.num_envs)
    eval_envs = {
        split: make_env(config, contexts, len(contexts))
        for split, contexts in (("train", train_set), ("test", test_set), ("val", val_set))
        if contexts is not None
    }
    targets = np.array([c.observed_target for c in train_set], dtype=np.int64)
    patterns = np.stack([c.pattern for c in train_set]).astype(np.int8)
    logger = RunLogger(run_dir, config, state)
    started = time.perf_counter() - state.wall_time_s
    # Process CPU time counts every thread: core-seconds, fair on a shared machine.
    started_cpu = time.process_time() - state.cpu_time_s

    def clock() -> None:
        state.wall_time_s = time.perf_counter() - started
        state.cpu_time_s = time.process_time() - started_cpu

    def evaluate() -> None:
        clock()
        returns = {
            split: greedy_returns(online, env, config.train.device, eval_seed)
            for split, env in eval_envs.items()
        }
        record_evaluation(state, config, returns, predictor is not None, run_dir, logger, online)

    eval_seed = stream_seed(config, EVAL_STREAM)
    if not state.metrics:
        evaluate()
    while state.episodes < config.total_episodes:
        epsilon = config.epsilon(state.episodes)
        # The environment's own draws are seeded per round, so a resumed run repeats them.
        collect_env.reset(seed=stream_seed(config, COLLECT_STREAM, state.episodes))
        contexts = state.rng.integers(len(train_set), size=config.train.num_envs)
        policy = EpsilonGreedyPolicy(
            online, epsilon, state.rng, config.train.device, config.train.explore_do_nothing
        )
        episodes: EpisodeBatch = run_episodes(collect_env, contexts, policy)
        replay.add(
            episodes.voltage, episodes.actions, episodes.rewards, targets[contexts],
            patterns[contexts], episodes.action_mask,
        )  # fmt: skip
        before = state.episodes
        state.episodes += config.train.num_envs
        logger.progress(config.train.num_envs, epsilon, float(episodes.returns.mean()))
        if len(replay) >= max(config.train.learning_starts, 1):
            set_learning_rate(optimizer, config.learning_rate(before))
            for _ in range(config.train.updates_per_round):
                batch = replay.sample(config.train.batch_size, state.rng)
                td, aux = training_losses(online, target, batch, config, predictor)
                loss = td if aux is None else td + config.train.aux_voltage_weight * aux
                if not torch.isfinite(loss):
                    raise RunDirError(
                        f"the training loss became {loss.item()} at update {state.updates + 1} "
                        f"(episode {state.episodes}): training diverged; the last good "
                        f"checkpoint in {run_dir} is kept (lower --learning-rate?)"
                    )
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                if config.train.max_grad_norm > 0:
                    torch.nn.utils.clip_grad_norm_(trained, config.train.max_grad_norm)
                optimizer.step()
                soft_update(target, online, config.train.tau)
                state.updates += 1
                state.loss_sum += td.item()
                state.aux_loss_sum += 0.0 if aux is None else aux.item()
                state.loss_count += 1
        finished = state.episodes >= config.total_episodes
        if finished or crossed_multiple(before, state.episodes, config.train.eval_every_episodes):
            evaluate()
        if finished or crossed_multiple(
            before, state.episodes, config.train.checkpoint_every_episodes
        ):
            clock()
            save_checkpoint(run_dir, config, state, online, target, optimizer, replay, predictor)
    logger.finish(online, state)
    if state.updates == 0:
        warnings.warn(
            f"the run in {run_dir} made no gradient update (learning_starts="
            f"{config.train.learning_starts}, updates_per_round="
            f"{config.train.updates_per_round}, "
            f"{config.total_episodes} episodes): model.pt is the untrained initial network",
            RuntimeWarning,
            stacklevel=2,
        )
    return state.metrics


def record_evaluation(
    state: TrainingState,
    config: Experiment,
    returns: dict[str, float],
    with_aux: bool,
    run_dir: Path,
    logger: RunLogger,
    network: torch.nn.Module,
) -> None:
    """Append one metrics.csv row (greedy ``returns`` per split, mean losses since the
    last row, both clocks), write it and log it; the loss sums start again. When the
    validation return beats every earlier one, ``network`` is saved as best_model.pt
    (model selection on the validation set, never on the test set)."""
    n = state.loss_count
    row = {
        "episode": state.episodes,
        "env_steps": state.episodes * config.env.episode_length,
        "updates": state.updates,
        "epsilon": config.epsilon(state.episodes),
        "train_return": float(returns["train"]),
        "test_return": float(returns["test"]),
        "loss": state.loss_sum / n if n else math.nan,
        "wall_time_s": state.wall_time_s,
        "val_return": float(returns["val"]) if "val" in returns else math.nan,
        "aux_loss": state.aux_loss_sum / n if n and with_aux else math.nan,
        "cpu_time_s": state.cpu_time_s,
    }
    state.loss_sum, state.aux_loss_sum, state.loss_count = 0.0, 0.0, 0
    state.metrics.append(row)
    write_metrics(run_dir, state.metrics, METRIC_FIELDS)
    logger.log(row)
    if best_on_validation(state.metrics) is row:
        save_model(run_dir, network, BEST_MODEL_FILE, episode=state.episodes)


def best_on_validation(metrics: list[dict]) -> dict | None:
    """The metrics row with the highest validation return (the earliest of equal ones),
    or None for a run without a validation set: the evaluation best_model.pt was taken at."""
    scored = [row for row in metrics if not math.isnan(row.get("val_return", math.nan))]
    return max(scored, key=lambda row: row["val_return"], default=None)


def baseline_episodes(config: Experiment, contexts, policy) -> EpisodeBatch:
    """A reference policy's episodes on a set, in the run's environment."""
    return evaluate_policy(
        contexts, policy, config.env.params, config.env.extensions.environment_part(),
        seed=stream_seed(config, EVAL_STREAM),
    )  # fmt: skip


def crossed_multiple(before: int, after: int, every: int) -> bool:
    """Whether a count went past a multiple of ``every`` going from ``before`` to ``after``
    (a round of episodes may cross an evaluation or checkpoint point without landing on it)."""
    return after // every > before // every


class RunLogger:
    """Progress bar and TensorBoard, both optional extras of a run (never its record)."""

    def __init__(self, run_dir: Path, config: Experiment, state: TrainingState) -> None:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm.auto import tqdm

        self.run_dir = run_dir
        # purge_step drops events a killed run logged after its last checkpoint.
        self.writer = SummaryWriter(str(run_dir / "tensorboard"), purge_step=state.episodes)
        self.bar = tqdm(
            total=config.total_episodes, initial=state.episodes, unit="ep",
            disable=not config.train.progress, dynamic_ncols=True, desc=config.agent.arch,
            mininterval=1.0,
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
        self.bar.close()
        self.writer.close()
        save_model(self.run_dir, online)
