"""K seeds of one configuration trained in one process, as one batched computation.

``train_group(configs, run_dirs, group_dir)`` trains K independent agents whose configs
differ only in ``seed`` and ``n_train`` (each seed collects on its own training set,
held in one collection environment as consecutive blocks): the online, target and
auxiliary networks of all seeds are stacked along a leading seed dimension
(``spikectl.agents.stacked``) and every forward, backward and optimiser step serves all
K at once. Each seed keeps what a run of its own
has: its replay buffer, its generator (the very stream ``dqn.train`` with that seed
draws from, in the same order), its epsilon schedule, its target network and auxiliary
head, its own gradient-norm clip and Adam moments (Adam is elementwise, so one Adam on
stacked parameters is K independent Adams). The loss backpropagated is the sum of the
seeds' losses, whose gradients never mix.

Each seed writes its own run directory with the files of a single run (config.json,
metrics.csv, baselines.json, context sets, tensorboard/, model.pt at the end), so
``spikectl evaluate`` and ``spikectl plot`` read it unchanged. The whole group's state
is one checkpoint, ``group_dir/group_checkpoint.pt``, written atomically, so a group
killed at any moment resumes exactly (``resume=True``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from spikectl.agents import make_agent
from spikectl.agents.stacked import StackedNetworks
from spikectl.contexts import ContextSet
from spikectl.envs.rollout import do_nothing_policy, make_random_policy, run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.training.checkpoint import (
    RunDirError,
    TrainingState,
    check_device,
    forget_best_model_after,
    run_lock,
    save_model,
)
from spikectl.training.config import Experiment
from spikectl.training.contexts import (
    COLLECT_STREAM,
    EVAL_STREAM,
    load_or_make_contexts,
    make_env,
    stream_seed,
)
from spikectl.training.dqn import (
    RunLogger,
    baseline_episodes,
    batch_tensors,
    build_networks,
    build_predictor,
    crossed_multiple,
    explore,
    greedy_returns,
    losses_on_tensors,
    record_evaluation,
    set_learning_rate,
)
from spikectl.training.group_files import (
    load_group_checkpoint,
    prepare_group,
    save_group_checkpoint,
)
from spikectl.training.replay import EpisodeReplay

SPLITS = ("train", "test", "val")
"""The evaluation splits, in the order ``load_or_make_contexts`` returns their sets."""


def group_key(config: Experiment) -> Experiment:
    """What the members of one seed group share: the config up to its seed and its
    training-set size (a group trains each seed on its own training set, so Figure 5's
    sizes can share one group)."""
    shared = config.with_seed(0)
    return dataclasses.replace(shared, env=dataclasses.replace(shared.env, n_train=1))


def seed_dirs(run_dir: str | Path, seeds: list[int]) -> list[Path]:
    """The seeds' run directories of a group trained with ``spikectl train --seeds``."""
    return [Path(run_dir) / f"seed={seed}" for seed in seeds]


def train_seeds(
    config: Experiment, seeds: list[int], run_dir: str | Path, resume: bool = False
) -> list[list[dict]]:
    """``config`` with each of ``seeds`` in one process: RUN_DIR/seed=S per seed."""
    if not seeds:
        raise ValueError("--seeds needs at least one seed")
    configs = [config.with_seed(seed) for seed in seeds]
    return train_group(configs, seed_dirs(run_dir, list(seeds)), run_dir, resume)


class GroupPolicy:
    """Acts for K seeds at once: the sub-environments hold K blocks of E episodes, block k
    played by seed k's online network with seed k's epsilon and generator."""

    def __init__(self, online: StackedNetworks, epsilon: float, rngs, config: Experiment):
        self.online, self.epsilon, self.rngs, self.config = online, epsilon, rngs, config
        self.state = None

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        K = self.online.size
        obs = {
            key: torch.as_tensor(
                np.asarray(observations[key]).astype(
                    np.float32 if key in ("voltage", "pattern") else np.int64, copy=False
                ),
                device=self.config.train.device,
            ).unflatten(0, (K, -1))  # [K, E, ...]
            for key in ("voltage", "target", "pattern", "step", "last_action")
        }
        if self.state is None:
            E, n = obs["voltage"].shape[1:]
            state = self.online.template.initial_state(E, n, device=self.config.train.device)
            self.state = tuple(s.expand(K, *s.shape).clone() for s in state)  # [K, E, ...]
        q_values, self.state = self.online.call("step", obs, self.state)  # [K, E, n+1]
        legal = torch.as_tensor(action_mask, device=q_values.device).unflatten(0, (K, -1))
        greedy = q_values.masked_fill(~legal, -math.inf).argmax(dim=2).cpu().numpy() - 1  # [K, E]
        if self.epsilon <= 0:
            return greedy.reshape(-1)
        masks = action_mask.reshape(K, -1, action_mask.shape[-1])  # [K, E, n+1]
        return np.concatenate([
            explore(greedy[k], masks[k], self.epsilon, self.rngs[k],
                    self.config.train.explore_do_nothing)
            for k in range(K)
        ])  # fmt: skip


def plain_networks(online: StackedNetworks, configs: list[Experiment]) -> list[torch.nn.Module]:
    """Each seed's online network as the plain module ``make_agent`` builds (nn.LSTM and
    all), holding that seed's current weights: what its model.pt will load into."""
    networks = []
    for k, config in enumerate(configs):
        network = make_agent(
            config.agent.arch, config.env.n_observed, config.env.episode_length,
            config.agent.sizes, params=config.env.params,
        )  # fmt: skip
        network.load_state_dict(online.state_dict(k))
        networks.append(network.to(config.train.device))
    return networks


def _check_group(configs: list[Experiment], run_dirs: list[Path]) -> None:
    if not configs:
        raise ValueError("a seed group needs at least one config")
    if len(configs) != len(run_dirs):
        raise ValueError(f"{len(configs)} configs but {len(run_dirs)} run directories")
    first = group_key(configs[0])
    for config in configs[1:]:
        if group_key(config) != first:
            raise ValueError(
                "the configs of a seed group may differ only in seed and n_train "
                "(the size of the training set)"
            )
    members = [(config.train.seed, config.env.n_train) for config in configs]
    if len(set(members)) != len(members):
        raise ValueError(
            f"the seeds of a group must be distinct (per training-set size), got "
            f"{[seed for seed, _ in members]}"
        )
    if len({Path(d).resolve() for d in run_dirs}) != len(run_dirs):
        raise ValueError("the seeds of a group need distinct run directories")


def train_group(
    configs: list[Experiment],
    run_dirs: list[str | Path],
    group_dir: str | Path,
    resume: bool = False,
) -> list[list[dict]]:
    """Train the seed group; returns each seed's metrics rows (also in its metrics.csv)."""
    run_dirs = [Path(d) for d in run_dirs]
    group_dir = Path(group_dir)
    _check_group(configs, run_dirs)
    check_device(configs[0].train.device)
    with contextlib.ExitStack() as locks:
        locks.enter_context(run_lock(group_dir))
        for run_dir in run_dirs:
            locks.enter_context(run_lock(run_dir))
        return _train_group(configs, run_dirs, group_dir, resume)


def _train_group(
    configs: list[Experiment], run_dirs: list[Path], group_dir: Path, resume: bool
) -> list[list[dict]]:
    config = configs[0]  # the settings every seed shares
    K, device = len(configs), config.train.device
    resume = prepare_group(configs, run_dirs, group_dir, resume)
    if config.train.torch_threads:
        torch.set_num_threads(config.train.torch_threads)
    sets = [load_or_make_contexts(c, d) for c, d in zip(configs, run_dirs, strict=True)]
    checksums = [[c.checksum() if c is not None else None for c in seed_sets] for seed_sets in sets]
    # Every seed collects on its own training set: the collection environment holds the
    # distinct training sets one after another, seed k's indices offset into its block.
    block_start: dict[str, int] = {}
    blocks: list[ContextSet] = []
    for (train_set, _, _), (train_sum, _, _) in zip(sets, checksums, strict=True):
        if train_sum not in block_start:
            block_start[train_sum] = sum(len(block) for block in blocks)
            blocks.append(train_set)
    offsets = [block_start[train_sum] for train_sum, _, _ in checksums]
    all_train = ContextSet(
        [context for block in blocks for context in block],
        params=blocks[0].params, extensions=blocks[0].extensions,
    )  # fmt: skip

    networks = [build_networks(c) for c in configs]
    online = StackedNetworks([pair[0] for pair in networks])
    target = StackedNetworks([pair[1] for pair in networks], trainable=False)
    predictors = [build_predictor(c, pair[0]) for c, pair in zip(configs, networks, strict=True)]
    predictor = None if predictors[0] is None else StackedNetworks(predictors)
    trained = online.parameters() + (predictor.parameters() if predictor else [])
    optimizer = torch.optim.Adam(trained, lr=config.train.learning_rate)
    replays = [
        EpisodeReplay(config.train.buffer_size, config.env.n_observed, config.env.episode_length)
        for _ in configs
    ]
    states = [TrainingState(rng=np.random.default_rng(np.random.SeedSequence(c.train.seed)))
              for c in configs]  # fmt: skip
    if resume:
        states = load_group_checkpoint(
            group_dir, configs, online, target, predictor, optimizer, replays
        )
        for state, run_dir in zip(states, run_dirs, strict=True):
            forget_best_model_after(run_dir, state.episodes)
    else:
        for c, state, (train_set, test_set, _) in zip(configs, states, sets, strict=True):
            state.baselines = {
                name: {
                    split: float(baseline_episodes(c, contexts, policy).returns.mean())
                    for split, contexts in (("train", train_set), ("test", test_set))
                }
                for name, policy in (
                    ("do_nothing", do_nothing_policy),
                    ("random", make_random_policy(c.train.seed)),
                )
            }  # fmt: skip

    E = config.train.num_envs
    collect_env = make_env(config, all_train, K * E)
    # One evaluation environment per distinct set; seed k scores on its own sets.
    envs_by_checksum: dict[str, NeuronControlVectorEnv] = {}
    seed_eval_envs: list[dict[str, NeuronControlVectorEnv]] = []  # [K] {split: env}
    for seed_sets, seed_sums in zip(sets, checksums, strict=True):
        for contexts, key in zip(seed_sets, seed_sums, strict=True):
            if contexts is not None and key not in envs_by_checksum:
                envs_by_checksum[key] = make_env(config, contexts, len(contexts))
        seed_eval_envs.append({
            split: envs_by_checksum[key]
            for split, key in zip(SPLITS, seed_sums, strict=True) if key is not None
        })  # fmt: skip
    targets = np.array([c.observed_target for c in all_train], dtype=np.int64)
    patterns = np.stack([c.pattern for c in all_train]).astype(np.int8)
    loggers = [
        RunLogger(
            d,
            dataclasses.replace(
                c, train=dataclasses.replace(c.train, progress=c.train.progress and k == 0)
            ),
            s,
        )
        for k, (c, d, s) in enumerate(zip(configs, run_dirs, states, strict=True))
    ]
    started = time.perf_counter() - states[0].wall_time_s
    started_cpu = time.process_time() - states[0].cpu_time_s

    def clock() -> None:
        for state in states:  # the group's clocks: every seed shares them
            state.wall_time_s = time.perf_counter() - started
            state.cpu_time_s = time.process_time() - started_cpu

    def evaluate() -> None:
        clock()
        # The plain networks score each seed exactly as `spikectl evaluate` scores its
        # model.pt (and as a single run scores the same weights).
        networks = plain_networks(online, configs)
        returns = {
            split: [
                greedy_returns(network, envs[split], device, seed)
                for network, seed, envs in zip(networks, eval_seeds, seed_eval_envs, strict=True)
            ]
            for split in seed_eval_envs[0]
        }
        for k, (state, run_dir) in enumerate(zip(states, run_dirs, strict=True)):
            seed_returns = {split: values[k] for split, values in returns.items()}
            record_evaluation(
                state, config, seed_returns, predictor is not None, run_dir, loggers[k], networks[k]
            )

    def seed_losses(online_params, target_params, predictor_params, tensors):
        td, aux = losses_on_tensors(
            online.bound(online_params), target.bound(target_params), tensors, config,
            None if predictor is None else predictor.bound(predictor_params),
        )  # fmt: skip
        return td, (torch.zeros_like(td) if aux is None else aux)

    batched_losses = torch.func.vmap(seed_losses, in_dims=(0, 0, 0 if predictor else None, 0))

    eval_seeds = [stream_seed(c, EVAL_STREAM) for c in configs]
    if not states[0].metrics:
        evaluate()
    while states[0].episodes < config.total_episodes:
        epsilon = config.epsilon(states[0].episodes)
        # Seed k's block of sub-environments draws what its single run's would.
        collect_env.reset(seed=[
            stream_seed(c, COLLECT_STREAM, states[0].episodes) + i for c in configs
            for i in range(E)
        ])  # fmt: skip
        contexts = np.concatenate([
            offset + state.rng.integers(len(seed_sets[0]), size=E)
            for offset, state, seed_sets in zip(offsets, states, sets, strict=True)
        ])  # fmt: skip  # [K*E], indices into all_train
        policy = GroupPolicy(online, epsilon, [s.rng for s in states], config)
        episodes = run_episodes(collect_env, contexts, policy)
        for k, replay in enumerate(replays):
            block = slice(k * E, (k + 1) * E)
            replay.add(
                episodes.voltage[block], episodes.actions[block], episodes.rewards[block],
                targets[contexts[block]], patterns[contexts[block]], episodes.action_mask[block],
            )  # fmt: skip
        before = states[0].episodes
        for state in states:
            state.episodes += E
        loggers[0].progress(E, epsilon, float(episodes.returns.mean()))  # episodes per seed
        if len(replays[0]) >= max(config.train.learning_starts, 1):
            set_learning_rate(optimizer, config.learning_rate(before))
            for _ in range(config.train.updates_per_round):
                seed_tensors = [
                    batch_tensors(replay.sample(config.train.batch_size, state.rng), device)
                    for replay, state in zip(replays, states, strict=True)
                ]
                tensors = stack_seeds(seed_tensors)  # every tensor [K, B, ...]
                td, aux = batched_losses(
                    online.params,
                    target.params,
                    predictor.params if predictor else None,
                    tensors,
                )  # td, aux: [K]
                losses = td if predictor is None else td + config.train.aux_voltage_weight * aux
                _check_finite_losses(losses, states, run_dirs)
                optimizer.zero_grad(set_to_none=True)
                losses.sum().backward()  # seeds' gradients stay apart: d(sum)/d(loss_k) = 1
                if config.train.max_grad_norm > 0:
                    clip_grad_norm_per_seed(trained, config.train.max_grad_norm)
                optimizer.step()
                with torch.no_grad():
                    for name in target.names:
                        target.params[name].lerp_(online.params[name], config.train.tau)
                for state, td_k, aux_k in zip(states, td.tolist(), aux.tolist(), strict=True):
                    state.updates += 1
                    state.loss_sum += td_k
                    state.aux_loss_sum += aux_k
                    state.loss_count += 1
        finished = states[0].episodes >= config.total_episodes
        if finished or crossed_multiple(
            before, states[0].episodes, config.train.eval_every_episodes
        ):
            evaluate()
        if finished or crossed_multiple(
            before, states[0].episodes, config.train.checkpoint_every_episodes
        ):
            clock()
            save_group_checkpoint(
                group_dir, configs, run_dirs, states, online, target, predictor, optimizer,
                replays,
            )  # fmt: skip
    for network, run_dir, logger in zip(
        plain_networks(online, configs), run_dirs, loggers, strict=True
    ):
        logger.bar.close()
        logger.writer.close()
        save_model(run_dir, network)
    if states[0].updates == 0:
        warnings.warn(
            f"the seed group in {group_dir} made no gradient update (learning_starts="
            f"{config.train.learning_starts}, updates_per_round="
            f"{config.train.updates_per_round}, "
            f"{config.total_episodes} episodes): each model.pt is the untrained initial network",
            RuntimeWarning,
            stacklevel=2,
        )
    return [state.metrics for state in states]


def stack_seeds(seed_tensors: list[dict]) -> dict:
    """K seeds' ``batch_tensors`` stacked into one dict of [K, ...] tensors."""
    first = seed_tensors[0]
    return {
        key: stack_seeds([seed[key] for seed in seed_tensors])
        if isinstance(first[key], dict)
        else torch.stack([seed[key] for seed in seed_tensors])
        for key in first
    }


def _check_finite_losses(losses: torch.Tensor, states, run_dirs) -> None:
    finite = torch.isfinite(losses)
    if not bool(finite.all()):
        k = int((~finite).nonzero()[0, 0])
        raise RunDirError(
            f"the training loss of seed {run_dirs[k].name} became {losses[k].item()} at update "
            f"{states[k].updates + 1} (episode {states[k].episodes}): training diverged; the "
            "group's last good checkpoint is kept (lower --learning-rate?)"
        )


@torch.no_grad()
def clip_grad_norm_per_seed(parameters: list[torch.Tensor], max_norm: float) -> torch.Tensor:
    """``torch.nn.utils.clip_grad_norm_`` for each seed of stacked parameters [K, ...]:
    seed k's gradients are scaled by min(1, max_norm / (‖g_k‖ + 1e-6)), where ‖g_k‖ is
    the 2-norm over all of seed k's gradients. Returns the norms [K]."""
    grads = [p.grad for p in parameters if p.grad is not None]
    K = grads[0].shape[0]
    norms = torch.stack(
        [torch.linalg.vector_norm(g.reshape(K, -1), 2, dim=1) for g in grads]
    )  # [P, K]
    total = torch.linalg.vector_norm(norms, 2, dim=0)  # [K]
    scale = torch.clamp(max_norm / (total + 1e-6), max=1.0)  # [K]
    for g in grads:
        g.mul_(scale.reshape(K, *([1] * (g.dim() - 1))))
    return total
