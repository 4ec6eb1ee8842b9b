"""The training loop: one loop for a single run and for a group of K seeds, any learner.

``train(config, run_dir)`` trains one run and returns its metrics rows;
``train_group(configs, run_dirs, group_dir)`` trains K seeds in one process (a single
run is a group of one, through the same code). A round, for all K seeds in lockstep:
each seed draws its ``num_envs`` training contexts from its own generator, the vector
environment plays all K blocks at once with the learners' collection policy, each seed's
learner takes its finished episodes and updates (``spikectl.training.learners``). Every
``eval_every_episodes`` each seed's network plays every training, test and validation
context greedily (a metrics.csv row, TensorBoard, best_model.pt when the validation
return is the best so far); every ``checkpoint_every_episodes`` the whole state is saved
in one file, so that ``resume=True`` continues bit-identically. The loop knows nothing
of Q-learning.

Seeds are independent: in a looped group (the default) a seed gives exactly the metrics
and weights of that seed trained alone; a stacked group (``stacked=True``) computes all
K in one batched computation, equal up to floating-point rounding (for GPUs).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import time
import warnings
from dataclasses import fields
from pathlib import Path

import numpy as np
import torch

from spikectl.envs.rollout import EpisodeBatch, run_episodes
from spikectl.seeds import COLLECT_STREAM, EVAL_STREAM
from spikectl.training.agent_network import check_initial_weights
from spikectl.training.best_model import kept_network, restore_best_model
from spikectl.training.checkpoint import RunState, load_checkpoint, save_checkpoint
from spikectl.training.config import Experiment
from spikectl.training.greedy_scores import greedy_returns
from spikectl.training.group import check_group, prepare_group, seed_dirs
from spikectl.training.learners import check_environment, check_stacked, make_learners
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.loop_envs import baselines, collection_env, evaluation_envs
from spikectl.training.machine import record_machine
from spikectl.training.run_files import (
    BEST_MODEL_FILE,
    RunDirError,
    check_device,
    check_run_path,
    prepare_run_dir,
    remove_unstarted,
    run_lock,
    write_metrics,
)
from spikectl.training.run_logger import RunLogger
from spikectl.training.run_sets import (
    TEST_FILE,
    TRAIN_FILE,
    VAL_FILE,
    load_or_make_contexts,
    recorded_config,
    stream_seed,
)
from spikectl.training.termination import TrainingTerminated, deferred_termination
from spikectl.training.torch_files import save_model

METRIC_FIELDS = (
    "episode", "env_steps", "updates", "train_return", "test_return", "loss",
    "wall_time_s", "val_return", "cpu_time_s", "eval_cpu_time_s",
)  # fmt: skip
"""The loop's columns of metrics.csv; the learner's ``metric_fields`` follow them (a
Q-learner's ``epsilon`` and ``aux_loss``, ...)."""


def train(config: Experiment, run_dir: str | Path, resume: bool = False) -> list[dict]:
    """Train one run; returns its metrics rows (also in ``run_dir/metrics.csv``).

    ``resume=True`` continues the run saved in ``run_dir`` from its last checkpoint
    (from step 0 if it stopped before its first). A loss that turns NaN or infinite
    stops the run with a RunDirError before anything more is written; a run that ends
    without a single gradient update warns (RuntimeWarning).
    """
    return train_runs([config], [run_dir], resume=resume)[0]


def train_group(
    configs: list[Experiment],
    run_dirs: list[str | Path],
    group_dir: str | Path,
    resume: bool = False,
    stacked: bool = False,
) -> list[list[dict]]:
    """Train a seed group (configs that differ only in seed and n_train) described by
    ``group_dir/group.json``; returns each seed's metrics rows."""
    return train_runs(configs, run_dirs, group_dir, resume, stacked)


def train_seeds(
    config: Experiment,
    seeds: list[int],
    run_dir: str | Path,
    resume: bool = False,
    stacked: bool = False,
) -> list[list[dict]]:
    """``config`` with each of ``seeds`` as one group: RUN_DIR/seed=S per seed."""
    if not seeds:
        raise ValueError("--seeds needs at least one seed")
    configs = [config.with_seed(seed) for seed in seeds]
    return train_runs(configs, seed_dirs(run_dir, list(seeds)), run_dir, resume, stacked)


def train_runs(
    configs: list[Experiment],
    run_dirs: list[str | Path],
    group_dir: str | Path | None = None,
    resume: bool = False,
    stacked: bool = False,
) -> list[list[dict]]:
    """The one training path: K >= 1 runs in this process, each in its run directory
    (all locked while they train), as a seed group when ``group_dir`` is given (whose
    directory then holds the checkpoint of all K)."""
    run_dirs = [Path(d) for d in run_dirs]
    # The group's directory first: its seed directories lie in it.
    directories = run_dirs if group_dir is None else [Path(group_dir), *run_dirs]
    for path in directories:
        check_run_path(path)
    check_group(configs, run_dirs)
    check_environment(configs)  # e.g. a teacher that cannot play it
    if stacked:
        check_stacked(configs)  # before any directory is made
    if not resume:
        for config in configs:  # weights that do not fit are refused before any directory
            check_initial_weights(config)
    configs = [recorded_config(c, d, resume) for c, d in zip(configs, run_dirs, strict=True)]
    check_device(configs[0].train.device)
    if group_dir is None and len(configs) > 1:
        raise ValueError("several runs in one process are a seed group: give group_dir")
    made = [path for path in directories if not os.path.lexists(path)]
    try:
        with contextlib.ExitStack() as locks:
            if group_dir is not None:
                locks.enter_context(run_lock(Path(group_dir)))
            for run_dir in run_dirs:
                locks.enter_context(run_lock(run_dir))
            if group_dir is None:
                where = run_dirs[0]
                resume = prepare_run_dir(configs[0], where, resume)
            else:
                where = Path(group_dir)
                resume = prepare_group(configs, run_dirs, where, resume, stacked)
            return Loop(configs, run_dirs, where, stacked).run(resume)
    except (ValueError, RunDirError, FileNotFoundError):
        # A refusal before the run's first evaluation (a bad context file, an
        # impossible task): the directories this call made go again, nothing half-made
        # stays. A Ctrl-C, SIGTERM or a failing disk keeps them: their message says to
        # resume, which restarts the run from step 0.
        remove_unstarted(made)
        raise


class Loop:
    """K seeds' runs in lockstep: files, contexts, environments, learners, state."""

    def __init__(
        self, configs: list[Experiment], run_dirs: list[Path], where: Path, stacked: bool
    ) -> None:
        self.configs, self.run_dirs, self.where, self.stacked = configs, run_dirs, where, stacked
        self.config = configs[0]  # the settings every seed shares
        self.K, self.E = len(configs), self.config.train.num_envs
        self.checkpointed = -1  # the episode count of this process's last checkpoint

    def run(self, resume: bool) -> list[list[dict]]:
        config, K = self.config, self.K
        if config.train.torch_threads:
            torch.set_num_threads(config.train.torch_threads)
        pairs = zip(self.configs, self.run_dirs, strict=True)
        sets = [load_or_make_contexts(config, run_dir) for config, run_dir in pairs]
        self.train_sets = [seed_sets[0] for seed_sets in sets]
        rngs = [np.random.default_rng(np.random.SeedSequence(c.train.seed)) for c in self.configs]
        # A resumed run's networks come from its checkpoint: the weights it started from
        # (agent.init_from) are not read again, and may be gone.
        starts = [
            dataclasses.replace(c, agent=dataclasses.replace(c.agent, init_from=None))
            if resume else c
            for c in self.configs
        ]  # fmt: skip
        self.learners = make_learners(starts, self.train_sets, rngs, self.stacked)
        extra = tuple(f for f in self.learners.metric_fields if f not in METRIC_FIELDS)
        self.metric_fields = METRIC_FIELDS + extra
        if resume:
            self.states = load_checkpoint(
                self.where, self.configs, self.learners, rngs, self.stacked
            )
            for k, (state, run_dir) in enumerate(zip(self.states, self.run_dirs, strict=True)):
                check_same_contexts(state, run_dir, sets[k])
                # The directory as it was at the checkpoint: what a killed run wrote
                # after it (metrics rows, best_model.pt) is written again exactly.
                write_metrics(run_dir, state.metrics, self.metric_fields)
                restore_best_model(
                    run_dir, state.best_model, state.episodes, self.learners.network(k)
                )
        else:
            self.states = [
                RunState(rng=rng, baselines=baselines(c, train_set, test_set),
                         contexts=context_checksums((train_set, test_set, val_set)))
                for rng, c, (train_set, test_set, val_set)
                in zip(rngs, self.configs, sets, strict=True)
            ]  # fmt: skip
        for run_dir, state in zip(self.run_dirs, self.states, strict=True):
            record_machine(run_dir, state.episodes)
        self.collect_env, self.offsets = collection_env(config, self.train_sets, self.E)
        self.eval_envs = evaluation_envs(config, sets)
        self.eval_seeds = [stream_seed(c, EVAL_STREAM) for c in self.configs]
        self.loggers = [
            RunLogger(d, config.total_episodes, s.episodes,
                      config.train.progress and k == 0, config.agent.arch, self.where)
            for k, (d, s) in enumerate(zip(self.run_dirs, self.states, strict=True))
        ]  # fmt: skip
        # Process CPU time counts every thread: core-seconds, fair on a shared machine.
        self.started = (
            time.perf_counter() - self.states[0].wall_time_s,
            time.process_time() - self.states[0].cpu_time_s,
        )
        with deferred_termination() as termination_requested:
            if not self.states[0].metrics:
                self.evaluate()
            while self.states[0].episodes < config.total_episodes:
                self.round()
                if termination_requested() and self.states[0].episodes < config.total_episodes:
                    # SIGTERM (Slurm, Docker): this round's end is a point to resume from.
                    if self.checkpointed != self.states[0].episodes:
                        self.checkpoint()
                    raise TrainingTerminated(self.where, self.states[0].episodes)
        for k, (run_dir, logger) in enumerate(zip(self.run_dirs, self.loggers, strict=True)):
            save_model(run_dir, self.learners.network(k))
            logger.close()  # TensorBoard last: its failure must cost no run file
        if any(self.learners.updates(k) == 0 for k in range(K)):
            warnings.warn(
                f"the run in {self.where} made no gradient update (learning_starts="
                f"{config.learner.learning_starts}, updates_per_round="
                f"{config.learner.updates_per_round}, {config.total_episodes} episodes): "
                "model.pt is the untrained initial network",
                RuntimeWarning,
                stacklevel=4,
            )
        return [state.metrics for state in self.states]

    def round(self) -> None:
        """Collect one round for every seed, let the learners learn, evaluate and
        checkpoint when the round crosses their points."""
        config, states, E = self.config, self.states, self.E
        before = states[0].episodes
        # Each seed's block of sub-environments draws what its single run's would; the
        # environment's own draws are seeded per round, so a resumed run repeats them.
        self.collect_env.reset(seed=[
            stream_seed(c, COLLECT_STREAM, before) + i for c in self.configs for i in range(E)
        ])  # fmt: skip
        contexts = [state.rng.integers(len(s), size=E)
                    for state, s in zip(states, self.train_sets, strict=True)]  # fmt: skip
        played = np.concatenate(
            [offset + c for offset, c in zip(self.offsets, contexts, strict=True)]
        )  # [K*E], indices into the collection environment's set
        episodes = run_episodes(self.collect_env, played, self.learners.collection_policy(before))
        blocks = [block(episodes, k * E, (k + 1) * E) for k in range(self.K)]
        self.learners.observe(blocks, contexts)
        for state in states:
            state.episodes += E
        self.loggers[0].progress(E, float(blocks[0].returns.mean()), self.learners.progress(before))
        try:
            self.learners.update(before)
        except LossDiverged as error:
            run_dir = self.run_dirs[error.seed]
            raise RunDirError(
                f"{error} (episode {states[0].episodes}{self._seed_label(run_dir)}): training "
                f"diverged; the last good checkpoint in {self.where} is kept "
                "(lower --learning-rate?)"
            ) from None
        after = states[0].episodes
        finished = after >= config.total_episodes
        if finished or crossed_multiple(before, after, config.train.eval_every_episodes):
            self.evaluate()
        if finished or crossed_multiple(before, after, config.train.checkpoint_every_episodes):
            self.checkpoint()

    def checkpoint(self) -> None:
        """Save the whole state of every seed at this round's end, the clocks first."""
        self.clock()
        save_checkpoint(
            self.where, self.configs, self.states, self.learners.state_dict(), self.run_dirs,
            self.stacked,
        )  # fmt: skip
        self.checkpointed = self.states[0].episodes

    def _seed_label(self, run_dir: Path) -> str:
        return "" if self.K == 1 else f", seed {run_dir.name}"

    def clock(self) -> None:
        """The group's clocks, which every seed shares (a single run's own)."""
        for state in self.states:
            state.wall_time_s = time.perf_counter() - self.started[0]
            state.cpu_time_s = time.process_time() - self.started[1]

    def evaluate(self) -> None:
        """Score each seed's network greedily on each of its sets: one metrics row per
        seed. When a seed's validation return beats every earlier one, its network is
        saved as best_model.pt (model selection on validation, never on test). A row's
        clocks stop before its own evaluation; the time it takes goes to the next row's."""
        self.clock()
        started = time.process_time()
        for k, (state, run_dir) in enumerate(zip(self.states, self.run_dirs, strict=True)):
            network = self.learners.network(k)
            returns = {
                split: greedy_returns(network, env, self.config.train.device, self.eval_seeds[k])
                for split, env in self.eval_envs[k].items()
            }
            row = {
                "episode": state.episodes,
                "env_steps": state.episodes * self.config.env.episode_length,
                **self.learners.row_metrics(k, state.episodes),
                "train_return": float(returns["train"]),
                "test_return": float(returns["test"]),
                "val_return": float(returns["val"]) if "val" in returns else math.nan,
                "wall_time_s": state.wall_time_s,
                "cpu_time_s": state.cpu_time_s,
                "eval_cpu_time_s": state.eval_cpu_time_s,
            }
            state.metrics.append(row)
            write_metrics(run_dir, state.metrics, self.metric_fields)
            if best_on_validation(state.metrics) is row:
                save_model(run_dir, network, BEST_MODEL_FILE, episode=state.episodes)
                state.best_model = kept_network(network, state.episodes)
            self.loggers[k].log(row, self.learners.metric_fields)
        evaluating = time.process_time() - started  # the group's, like its other clocks
        for state in self.states:
            state.eval_cpu_time_s += evaluating


SPLIT_FILES = {"train": TRAIN_FILE, "test": TEST_FILE, "validation": VAL_FILE}


def context_checksums(seed_sets) -> dict[str, str]:
    """The checksum of each of a run's context sets (train, test, validation or None)."""
    return {split: contexts.checksum()
            for split, contexts in zip(SPLIT_FILES, seed_sets, strict=True)
            if contexts is not None}  # fmt: skip


def check_same_contexts(state: RunState, run_dir: Path, seed_sets) -> None:
    """Refuse to resume a run on context sets other than those it started on (a valid
    file swapped in would otherwise train and score on other networks, silently)."""
    found = context_checksums(seed_sets)
    for split, recorded in state.contexts.items():
        if found.get(split) != recorded:
            raise RunDirError(
                f"{run_dir / SPLIT_FILES[split]} is not the {split} set this run started "
                f"on (checksum {str(found.get(split))[:12]}, recorded {recorded[:12]}): put "
                "the run's own file back, or start a new run on these contexts"
            )


def block(episodes: EpisodeBatch, start: int, stop: int) -> EpisodeBatch:
    """Episodes ``start:stop`` of a batch."""
    return EpisodeBatch(**{
        field.name: getattr(episodes, field.name)[start:stop] for field in fields(EpisodeBatch)
    })  # fmt: skip


def best_on_validation(metrics: list[dict]) -> dict | None:
    """The metrics row with the highest validation return (the earliest of equal ones),
    or None for a run without a validation set: the evaluation best_model.pt was taken at."""
    scored = [row for row in metrics if not math.isnan(row.get("val_return", math.nan))]
    return max(scored, key=lambda row: row["val_return"], default=None)


def crossed_multiple(before: int, after: int, every: int) -> bool:
    """Whether a count went past a multiple of ``every`` going from ``before`` to ``after``
    (a round of episodes may cross an evaluation or checkpoint point without landing on it)."""
    return after // every > before // every
