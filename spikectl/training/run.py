"""The training loop: one loop for a single run and for a group of K seeds, any learner.

``train(config, run_dir)`` trains one run and returns its metrics rows;
``train_group(configs, run_dirs, group_dir)`` trains K seeds in one process, a round of
each in turn (a single run is a group of one, through the same code). Per seed, a round
is: choose ``num_envs`` training contexts with the run's generator, play them at once in
the vector environment with the learner's collection policy, hand the finished episodes
to the learner and let it update (``spikectl.training.learners``). Every
``eval_every_episodes`` the learner's network plays every training, test and validation
context greedily (a metrics.csv row, TensorBoard, best_model.pt when the validation
return is the best so far); every ``checkpoint_every_episodes`` the seed's whole state
is saved, so that ``resume=True`` continues bit-identically, and a group resumes every
seed from its own checkpoint. The loop knows nothing of Q-learning.

Seeds are independent: a seed trained in a group gives exactly the metrics and weights
of that seed trained alone.
"""

from __future__ import annotations

import contextlib
import math
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

from spikectl.envs.rollout import do_nothing_policy, make_random_policy, run_episodes
from spikectl.training.checkpoint import RunState, load_checkpoint, save_checkpoint
from spikectl.training.config import Experiment
from spikectl.training.contexts import (
    COLLECT_STREAM,
    EVAL_STREAM,
    baseline_episodes,
    load_or_make_contexts,
    make_env,
    stream_seed,
)
from spikectl.training.greedy import greedy_returns
from spikectl.training.group import check_group, prepare_group, seed_dirs
from spikectl.training.learners import make_learner
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.run_files import (
    BEST_MODEL_FILE,
    CONFIG_FILE,
    RunDirError,
    check_device,
    prepare_run_dir,
    run_lock,
    write_metrics,
)
from spikectl.training.run_logger import RunLogger
from spikectl.training.torch_files import forget_best_model_after, save_model

METRIC_FIELDS = (
    "episode", "env_steps", "updates", "epsilon", "train_return", "test_return", "loss",
    "wall_time_s", "val_return", "aux_loss", "cpu_time_s",
)  # fmt: skip
"""metrics.csv's columns; a learner's other ``metric_fields`` follow them."""
SPLITS = ("train", "test", "val")


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
) -> list[list[dict]]:
    """Train a seed group (configs that differ only in seed and n_train) described by
    ``group_dir/group.json``; returns each seed's metrics rows. ``resume=True`` resumes
    every seed from its own checkpoint."""
    return train_runs(configs, run_dirs, group_dir, resume)


def train_seeds(
    config: Experiment, seeds: list[int], run_dir: str | Path, resume: bool = False
) -> list[list[dict]]:
    """``config`` with each of ``seeds`` as one group: RUN_DIR/seed=S per seed."""
    if not seeds:
        raise ValueError("--seeds needs at least one seed")
    configs = [config.with_seed(seed) for seed in seeds]
    return train_runs(configs, seed_dirs(run_dir, list(seeds)), run_dir, resume)


def train_runs(
    configs: list[Experiment],
    run_dirs: list[str | Path],
    group_dir: str | Path | None = None,
    resume: bool = False,
) -> list[list[dict]]:
    """The one training path: K >= 1 runs in this process, each in its run directory
    (locked for the whole time), as a seed group when ``group_dir`` is given."""
    run_dirs = [Path(d) for d in run_dirs]
    check_group(configs, run_dirs)
    check_device(configs[0].train.device)
    with contextlib.ExitStack() as locks:
        if group_dir is not None:
            locks.enter_context(run_lock(Path(group_dir)))
        for run_dir in run_dirs:
            locks.enter_context(run_lock(run_dir))
        if group_dir is not None:
            prepare_group(configs, run_dirs, Path(group_dir), resume)
        seeds = []
        for config, run_dir in zip(configs, run_dirs, strict=True):
            # A group's seed that wrote its config continues (or starts again when it
            # stopped before its first checkpoint); a single run does as it is told.
            continues = (run_dir / CONFIG_FILE).exists() if group_dir is not None else resume
            seeds.append(SeedRun(config, run_dir, prepare_run_dir(config, run_dir, continues)))
        return _train(seeds, Path(group_dir) if group_dir is not None else run_dirs[0])


def _train(seeds: list[SeedRun], where: Path) -> list[list[dict]]:
    threads = seeds[0].config.train.torch_threads
    if threads:
        torch.set_num_threads(threads)
    for k, seed in enumerate(seeds):
        seed.start(show_progress=k == 0)
    while any(not seed.finished for seed in seeds):
        for seed in seeds:
            if not seed.finished:
                seed.round()
    for seed in seeds:
        seed.finish()
    if any(seed.learner.updates == 0 for seed in seeds):
        config = seeds[0].config
        warnings.warn(
            f"the run in {where} made no gradient update (learning_starts="
            f"{config.learner.learning_starts}, updates_per_round="
            f"{config.learner.updates_per_round}, "
            f"{config.total_episodes} episodes): model.pt is the untrained initial network",
            RuntimeWarning,
            stacklevel=3,
        )
    return [seed.state.metrics for seed in seeds]


class SeedRun:
    """One seed's run inside the loop: its contexts, environments, learner, state, files."""

    def __init__(self, config: Experiment, run_dir: Path, resume: bool) -> None:
        self.config, self.run_dir, self.resume = config, run_dir, resume
        self._block: tuple[float, float] | None = None

    def start(self, show_progress: bool) -> None:
        """Load or make the context sets, build the learner and environments, restore the
        checkpoint or score the baselines, and make the first evaluation."""
        config = self.config
        self.train_set, test_set, val_set = load_or_make_contexts(config, self.run_dir)
        rng = np.random.default_rng(np.random.SeedSequence(config.train.seed))
        self.learner = make_learner(config, self.train_set, rng)
        self.state = RunState(rng=rng)
        if self.resume:
            self.state = load_checkpoint(self.run_dir, config, self.learner, rng)
            forget_best_model_after(self.run_dir, self.state.episodes)
        else:
            self.state.baselines = {
                name: {
                    split: float(baseline_episodes(config, contexts, policy).returns.mean())
                    for split, contexts in (("train", self.train_set), ("test", test_set))
                }
                for name, policy in (
                    ("do_nothing", do_nothing_policy),
                    ("random", make_random_policy(config.train.seed)),
                )
            }
        self.collect_env = make_env(config, self.train_set, config.train.num_envs)
        self.eval_envs = {
            split: make_env(config, contexts, len(contexts))
            for split, contexts in zip(SPLITS, (self.train_set, test_set, val_set), strict=True)
            if contexts is not None
        }
        self.eval_seed = stream_seed(config, EVAL_STREAM)
        self.logger = RunLogger(
            self.run_dir, config.total_episodes, self.state.episodes,
            show_progress and config.train.progress, config.agent.arch,
        )  # fmt: skip
        if not self.state.metrics:
            with self.timed():
                self.evaluate()

    @property
    def finished(self) -> bool:
        return self.state.episodes >= self.config.total_episodes

    def round(self) -> None:
        """Collect one round of episodes, let the learner learn, evaluate and checkpoint
        when the round crosses their points."""
        config, state = self.config, self.state
        with self.timed():
            # The environment's own draws are seeded per round, so a resumed run repeats them.
            self.collect_env.reset(seed=stream_seed(config, COLLECT_STREAM, state.episodes))
            contexts = state.rng.integers(len(self.train_set), size=config.train.num_envs)
            policy = self.learner.collection_policy(state.episodes)
            episodes = run_episodes(self.collect_env, contexts, policy)
            self.learner.observe(episodes, contexts)
            before = state.episodes
            state.episodes += config.train.num_envs
            self.logger.progress(
                config.train.num_envs, float(episodes.returns.mean()),
                self.learner.progress(before),
            )  # fmt: skip
            try:
                self.learner.update(before)
            except LossDiverged as error:
                raise RunDirError(
                    f"{error} (episode {state.episodes}): training diverged; the last good "
                    f"checkpoint in {self.run_dir} is kept (lower --learning-rate?)"
                ) from None
            if self.finished or crossed_multiple(
                before, state.episodes, config.train.eval_every_episodes
            ):
                self.evaluate()
            if self.finished or crossed_multiple(
                before, state.episodes, config.train.checkpoint_every_episodes
            ):
                state.wall_time_s, state.cpu_time_s = self.clocks().values()
                self._block = (time.perf_counter(), time.process_time())
                save_checkpoint(self.run_dir, config, state, self.learner.state_dict())

    def evaluate(self) -> None:
        """Score the learner's network greedily on every set: one metrics row. When the
        validation return beats every earlier one, the network is saved as
        best_model.pt (model selection on the validation set, never on the test set)."""
        network, state = self.learner.network, self.state
        returns = {
            split: greedy_returns(network, env, self.config.train.device, self.eval_seed)
            for split, env in self.eval_envs.items()
        }
        row = {
            "episode": state.episodes,
            "env_steps": state.episodes * self.config.env.episode_length,
            **self.learner.row_metrics(state.episodes),
            "train_return": float(returns["train"]),
            "test_return": float(returns["test"]),
            "val_return": float(returns["val"]) if "val" in returns else math.nan,
            **self.clocks(),
        }
        state.metrics.append(row)
        extra = tuple(name for name in self.learner.metric_fields if name not in METRIC_FIELDS)
        write_metrics(self.run_dir, state.metrics, METRIC_FIELDS + extra)
        self.logger.log(row)
        if best_on_validation(state.metrics) is row:
            save_model(self.run_dir, network, BEST_MODEL_FILE, episode=state.episodes)

    def finish(self) -> None:
        self.logger.close()
        save_model(self.run_dir, self.learner.network)

    @contextlib.contextmanager
    def timed(self) -> Iterator[None]:
        """Count the block's wall and process CPU time on this seed's clocks: a group's
        seeds each count their own time, so core-minutes stay per seed."""
        self._block = (time.perf_counter(), time.process_time())
        try:
            yield
        finally:
            self.state.wall_time_s, self.state.cpu_time_s = self.clocks().values()
            self._block = None

    def clocks(self) -> dict[str, float]:
        """This seed's clocks now: what it has counted, plus the running block's time."""
        wall, cpu = self.state.wall_time_s, self.state.cpu_time_s
        if self._block is not None:
            wall += time.perf_counter() - self._block[0]
            cpu += time.process_time() - self._block[1]
        return {"wall_time_s": wall, "cpu_time_s": cpu}


def best_on_validation(metrics: list[dict]) -> dict | None:
    """The metrics row with the highest validation return (the earliest of equal ones),
    or None for a run without a validation set: the evaluation best_model.pt was taken at."""
    scored = [row for row in metrics if not math.isnan(row.get("val_return", math.nan))]
    return max(scored, key=lambda row: row["val_return"], default=None)


def crossed_multiple(before: int, after: int, every: int) -> bool:
    """Whether a count went past a multiple of ``every`` going from ``before`` to ``after``
    (a round of episodes may cross an evaluation or checkpoint point without landing on it)."""
    return after // every > before // every
