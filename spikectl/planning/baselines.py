"""Score every training-free controller on a context set: the table of `spikectl baselines`.

Do nothing, uniformly random legal actions (10 seeds), identify-and-plan, the oracle
planner (its plan replayed open loop in the environment) and the witness, each a
controller (:mod:`spikectl.envs.controller`) played on every context of a set through
the vector environment, so that environment-level extensions (noise, stochastic
release, background input) act on all of them alike.
"""

from __future__ import annotations

import csv
import io
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.controller import Controller, DoNothing, RandomLegal, Witness
from spikectl.envs.rollout import run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.files import atomic_write_text
from spikectl.neuron.extensions import CONTEXT_FIELDS, Extensions
from spikectl.planning.lit_search import planned_light
from spikectl.planning.oracle import DEFAULT_ORACLE_WIDTH, OraclePlanner
from spikectl.planning.policy import IdentifyAndPlan

BASELINE_ROWS = ("do_nothing", "random", "identify_and_plan", "oracle", "witness")
"""The rows of ``spikectl baselines``, in order: its own fixed table with adjustable beam
widths (the named controllers of ``spikectl benchmark`` are the registry's,
:data:`spikectl.training.loaders.CONTROLLERS`)."""


@dataclass
class BaselineResults:
    """Per-context returns [S] of each controller, and what the table needs besides."""

    returns: dict[str, np.ndarray]
    """controller -> [S] returns (random: the mean over its seeds)."""
    random_seed_means: np.ndarray
    """[seeds] mean return of the random policy per seed (for mean +- sd)."""
    identify_seconds_per_episode: float
    """CPU seconds per episode of identify-and-plan (process time, whole batch / S)."""
    oracle_seconds_per_context: float
    """CPU seconds per context of the oracle planner."""
    extra: dict[str, float] = field(default_factory=dict)

    def table(self) -> str:
        """The printed table: mean return of each controller."""
        lines = [f"{'controller':<20}{'mean return':>16}"]
        for name in BASELINE_ROWS:
            if name not in self.returns:
                continue
            if name == "random":
                seeds = self.random_seed_means
                value = f"{seeds.mean():.3f} +- {seeds.std(ddof=1) if seeds.size > 1 else 0:.3f}"
            else:
                value = f"{self.returns[name].mean():.3f}"
            lines.append(f"{name.replace('_', '-'):<20}{value:>16}")
        lines.append(
            f"identify-and-plan: {self.identify_seconds_per_episode:.3f} CPU s per episode; "
            f"oracle: {self.oracle_seconds_per_context:.3f} CPU s per context"
        )
        return "\n".join(lines)

    def write_csv(self, path: str | os.PathLike, replace: bool = True) -> Path:
        """One row per context, one column per controller; written atomically
        (``replace=False``: never over an existing file)."""
        names = [name for name in BASELINE_ROWS if name in self.returns]
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(["context", *names])
        size = next(iter(self.returns.values())).shape[0]
        for index in range(size):
            writer.writerow([index, *(f"{self.returns[name][index]:.6f}" for name in names)])
        return atomic_write_text(path, buffer.getvalue(), replace)


def run_baselines(
    contexts: ContextSet,
    *,
    extensions: Extensions | None = None,
    random_seeds: int = 10,
    oracle_width: int = DEFAULT_ORACLE_WIDTH,
    policy: IdentifyAndPlan | None = None,
    env_seed: int = 0,
) -> BaselineResults:
    """Score the controllers of :data:`BASELINE_ROWS` on every context of ``contexts``.

    Args:
        contexts: the set to play (one episode per context and controller), under the
            neuron parameters it was made with (``contexts.params``).
        extensions: environment-level extensions to play with (the context-level ones
            come from the set); None: the set's own.
        random_seeds: seeds 0 .. random_seeds - 1 of the random policy.
        oracle_width: beam width of the oracle planner.
        policy: the identify-and-plan controller; when None, ``IdentifyAndPlan(
            contexts.params, extensions=...)``, the paper's composition told the
            environment's measurement noise.
        env_seed: seed of the environments' generators (noise, stochastic release).
    """
    if random_seeds < 1:
        raise ValueError(f"random_seeds must be >= 1, got {random_seeds}")
    if extensions is not None:
        # The environment-level switches asked for, the context-level ones of the set.
        extensions = replace(
            Extensions.coerce(extensions),
            **{name: getattr(contexts.extensions, name) for name in CONTEXT_FIELDS},
        )
    env = NeuronControlVectorEnv(num_envs=len(contexts), contexts=contexts, extensions=extensions)
    params = contexts.params
    if policy is None:
        policy = IdentifyAndPlan(params, extensions=env.extensions)
    indices = np.arange(len(contexts))

    def play(controller: Controller) -> np.ndarray:
        env.reset(seed=env_seed)
        return run_episodes(env, indices, controller).returns

    returns = {"do_nothing": play(DoNothing())}
    seed_returns = np.stack([play(RandomLegal(seed)) for seed in range(random_seeds)])
    returns["random"] = seed_returns.mean(axis=0)
    started = time.process_time()
    returns["identify_and_plan"] = play(policy)
    identify_seconds = (time.process_time() - started) / len(contexts)
    oracle = OraclePlanner(contexts, params, oracle_width, env.extensions.allow_target_action,
                           light_mW_per_mm2=planned_light(env.extensions))
    returns["oracle"] = play(oracle)
    oracle_seconds = oracle.plan_seconds / len(contexts)
    if all(context.witness is not None for context in contexts):
        returns["witness"] = play(Witness(contexts))
    env.close()
    return BaselineResults(returns, seed_returns.mean(axis=1), identify_seconds, oracle_seconds)
