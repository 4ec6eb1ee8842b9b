"""The frozen benchmark suite (docs/benchmark.md): tasks, context sets pinned by checksum,
one evaluation protocol and the normalised score.

Each task is a registered environment (``spikectl/NeuronControl-v0`` or one of its
variants, with a few settings changed) and a network size. Its train, validation and
test sets are ``make_splits(100, 100, n, seed=TASK.seed, extensions=..., n_val=100)``,
generated on demand (a fraction of a second each) and checked against the SHA-256
checksums pinned in :data:`CHECKSUMS` for :data:`SUITE_VERSION`: a generator that drew
other networks raises :class:`SuiteChecksumError` naming the task and the version,
never plays other networks under the suite's name.

The protocol (:func:`score`): the controller is greedy (deterministic), plays every
context of the split once, through the vector environment whose generator (measurement
noise, stochastic release, background input) is seeded with :data:`ENV_SEED`. A score
is the mean return R and its normalised form (R - R_nothing) / (R_oracle - R_nothing):
do nothing is 0 and the oracle planner (the privileged planner that knows the network)
is 1, both played under the same protocol on the same split.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from spikectl.contexts import ContextSet, make_splits
from spikectl.envs.controller import Controller
from spikectl.envs.registration import ENV_ID, VARIANTS
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams

SUITE_VERSION = 1
"""Bumped whenever a task or one of its sets changes; results of two versions do not compare."""
SET_SIZE = 100
"""Contexts in each of a task's train, validation and test sets."""
EPISODE_LENGTH = 60
"""Steps per episode (the paper's)."""
ENV_SEED = 0
"""Seed of the environments' generators in the protocol (noise, release, background)."""
SPLITS = ("train", "validation", "test")

_REALISTIC = VARIANTS["spikectl/NeuronControlRealistic-v0"]["extensions"]
"""The moderate strengths of the registered all-in-one variant, reused one at a time."""


@dataclass(frozen=True)
class Task:
    """One task of the suite: a registered environment, its overrides and a seed."""

    name: str
    """The task's name on the command line and in tables."""
    env_id: str
    """The registered environment id the task is a setting of."""
    overrides: dict[str, Any]
    """Extension fields changed from the registered environment's (JSON-ready)."""
    n_neurons: int
    """Network size n."""
    seed: int
    """The generation seed of make_splits."""
    description: str
    """One line for tables and docs."""

    @property
    def extensions(self) -> Extensions:
        """Every extension of the task: the registered environment's, then the overrides."""
        registered = {ENV_ID: {}, **VARIANTS}[self.env_id].get("extensions", {})
        return Extensions.coerce({**registered, **self.overrides})

    @property
    def n_observed(self) -> int:
        """k, the neurons an agent sees (n less the hidden ones)."""
        return self.n_neurons - self.extensions.hidden_count(self.n_neurons)


def _task(name, env_id, n, description, **overrides) -> Task:
    # Seed 0 for every task: the paper's sets (every table of docs/baselines.md plays
    # make_splits(100, 100, seed=0, n_val=100)), and the environment-level variants play
    # the very networks of `paper`, so that their differences are the variant's alone.
    return Task(name, env_id, dict(overrides), n, 0, description)


TASKS: dict[str, Task] = {
    task.name: task
    for task in (
        _task("paper", ENV_ID, 8, "the paper's task, n = 8"),
        _task("n16", ENV_ID, 16, "n = 16 neurons, the same topology rule"),
        _task("n32", "spikectl/NeuronControl32-v0", 32, "n = 32 neurons"),
        _task("noise1", "spikectl/NeuronControlNoisy-v0", 8, "measurement noise 1 mV",
              observation_noise_mV=1.0),
        _task("noise2", "spikectl/NeuronControlNoisy-v0", 8, "measurement noise 2 mV"),
        _task("noise4", "spikectl/NeuronControlNoisy-v0", 8, "measurement noise 4 mV",
              observation_noise_mV=4.0),
        _task("hidden25", "spikectl/NeuronControlPartial-v0", 8,
              "25% of the neurons hidden (2 of 8)"),
        _task("stochastic", ENV_ID, 8, "stochastic release",
              stochastic_release=_REALISTIC["stochastic_release"]),
        _task("heterogeneous", ENV_ID, 8, "heterogeneous neurons and synapses (spreads 0.1)",
              **{name: _REALISTIC[name] for name in
                 ("threshold_spread", "time_constant_spread", "synaptic_spread")}),
        _task("background", ENV_ID, 8, "background activity (0.005 inputs / neuron / step)",
              background_rate=_REALISTIC["background_rate"]),
    )  # fmt: skip
}
"""The tasks of :data:`SUITE_VERSION`, in table order."""

CHECKSUMS: dict[str, dict[str, str]] = {
    "paper": {
        "train": "6e29cda2628b80eca90418f3b3ac7368b9149b24906d699e0996befae3b491e6",
        "validation": "bc6a85715aeab6a1418b714191997cf5b47495ce008d18caeaac81d390e18d0c",
        "test": "0f108c061d011e451cb9b28f9c3583bdb59e9733ecc90cee5ea9a182d02dffd7",
    },
    "n16": {
        "train": "6ccd03fea2ed4fb51dad990c98cecfaaeb45b0da647e703cfbda41e3304b77d5",
        "validation": "5e2ba51c75224b1d2d951c028bd95ecfc21a56694f8f933d069961d9d84549fd",
        "test": "6a0f803e8251aedbc5fe3c8c4c991897dcb2122a783ca0c4cd777d15a5755af9",
    },
    "n32": {
        "train": "c98e9c77be03c6bfcfa9c8b0241731aa443b4af0da3d68589a9cc30e69676251",
        "validation": "7afd9239cfcdba9fe174173326dea501183e4d425f9e41eaa12884d7fc20ba46",
        "test": "267aed93f155bc1d45cb5b681ad3c38a70dd847682a2841fbb84cf2bfd534598",
    },
    "noise1": {
        "train": "6e29cda2628b80eca90418f3b3ac7368b9149b24906d699e0996befae3b491e6",
        "validation": "bc6a85715aeab6a1418b714191997cf5b47495ce008d18caeaac81d390e18d0c",
        "test": "0f108c061d011e451cb9b28f9c3583bdb59e9733ecc90cee5ea9a182d02dffd7",
    },
    "noise2": {
        "train": "6e29cda2628b80eca90418f3b3ac7368b9149b24906d699e0996befae3b491e6",
        "validation": "bc6a85715aeab6a1418b714191997cf5b47495ce008d18caeaac81d390e18d0c",
        "test": "0f108c061d011e451cb9b28f9c3583bdb59e9733ecc90cee5ea9a182d02dffd7",
    },
    "noise4": {
        "train": "6e29cda2628b80eca90418f3b3ac7368b9149b24906d699e0996befae3b491e6",
        "validation": "bc6a85715aeab6a1418b714191997cf5b47495ce008d18caeaac81d390e18d0c",
        "test": "0f108c061d011e451cb9b28f9c3583bdb59e9733ecc90cee5ea9a182d02dffd7",
    },
    "hidden25": {
        "train": "4ed60bbbc42c04fc13ff829f47595da80ee2c78d54fb0b8b9fa9cd895ef21f6a",
        "validation": "80f4364ca9a2f696c2cab8e71816bea457adab572f6642a1c5c1063346880f83",
        "test": "ebb850b1c88658436703f38517144124cdb79164e6496eb2666aaba9a711d643",
    },
    "stochastic": {
        "train": "6e29cda2628b80eca90418f3b3ac7368b9149b24906d699e0996befae3b491e6",
        "validation": "bc6a85715aeab6a1418b714191997cf5b47495ce008d18caeaac81d390e18d0c",
        "test": "0f108c061d011e451cb9b28f9c3583bdb59e9733ecc90cee5ea9a182d02dffd7",
    },
    "heterogeneous": {
        "train": "9e60fbbf136024a6de28291a10ff0d25863043f335733bc4f0781a1938786ab7",
        "validation": "51e2414b84807b5b9fdde0ab517c128281f0e0fd41e885048421d13e711ceced",
        "test": "3baca2cdfba3cf78de757e280f492f6ce2600ae5b00ec00e34e048c24037bd6d",
    },
    "background": {
        "train": "6e29cda2628b80eca90418f3b3ac7368b9149b24906d699e0996befae3b491e6",
        "validation": "bc6a85715aeab6a1418b714191997cf5b47495ce008d18caeaac81d390e18d0c",
        "test": "0f108c061d011e451cb9b28f9c3583bdb59e9733ecc90cee5ea9a182d02dffd7",
    },
}  # fmt: skip
"""task -> split -> :func:`suite_checksum` of the set, pinned for :data:`SUITE_VERSION`
(the environment-level variants share the paper's networks, hence its checksums)."""


class SuiteChecksumError(ValueError):
    """A generated set is not the one the suite pinned: the generator changed."""


def suite_checksum(contexts: ContextSet) -> str:
    """SHA-256 of what defines a set (``ContextSet.checksum`` with the heterogeneous
    parameters rounded to 1e-9 as integers): exact values only, so it holds on any
    machine whose generator draws the same."""
    return contexts.checksum(round_floats=True)


def task(name: str) -> Task:
    """The task called ``name``; an unknown name is a ValueError listing the known ones."""
    if name not in TASKS:
        raise ValueError(
            f"unknown task {name!r} of benchmark suite v{SUITE_VERSION}; tasks: "
            f"{', '.join(TASKS)}"
        )
    return TASKS[name]


def train_arguments(name: str) -> list[str]:
    """The ``spikectl train`` flags that train on task ``name``: its environment, n,
    extension overrides and its sets' sizes and seed, so that the run's training and
    validation sets are the task's (tested) whatever the preset's own sizes (the guided
    preset trains on 1 000 networks)."""
    spec = task(name)
    arguments = ["--env", spec.env_id, "--n-neurons", str(spec.n_neurons),
                 "--episode-length", str(EPISODE_LENGTH)]  # fmt: skip
    for flag in ("--n-train", "--n-test", "--n-val"):
        arguments += [flag, str(SET_SIZE)]
    arguments += ["--context-seed", str(spec.seed)]
    for field_name, value in spec.overrides.items():
        flag = "--extensions." + field_name.replace("_", "-")
        if isinstance(value, bool):
            arguments.append(flag if value else flag.replace("--extensions.", "--extensions.no-"))
        else:
            arguments += [flag, repr(value)]
    return arguments


def generate_splits(name: str) -> dict[str, ContextSet]:
    """A task's three sets as generated by today's code, unchecked (see :func:`load_splits`)."""
    spec = task(name)
    train, test, validation = make_splits(
        SET_SIZE, SET_SIZE, spec.n_neurons, EPISODE_LENGTH, seed=spec.seed,
        extensions=spec.extensions.context_part(), n_val=SET_SIZE,
    )  # fmt: skip
    return {"train": train, "validation": validation, "test": test}


@functools.cache
def load_splits(name: str) -> dict[str, ContextSet]:
    """A task's train, validation and test sets, each checked against its pinned checksum;
    a set that differs raises :class:`SuiteChecksumError` naming the task and version."""
    sets = generate_splits(name)
    for split, contexts in sets.items():
        expected = CHECKSUMS.get(name, {}).get(split)
        actual = suite_checksum(contexts)
        if actual != expected:
            raise SuiteChecksumError(
                f"benchmark suite v{SUITE_VERSION}, task {name!r}, {split} set: the generated "
                f"networks do not match the pinned checksum ({actual[:12]}... instead of "
                f"{(expected or 'none')[:12]}...): the context generator has changed, so these "
                "are not the suite's networks and their scores would not compare; a changed "
                "generator needs a new SUITE_VERSION with new checksums"
            )
    return sets


def load_split(name: str, split: str = "test") -> ContextSet:
    """One checked set of a task (``split``: train, validation or test)."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    return load_splits(name)[split]


@dataclass(frozen=True)
class Score:
    """One controller on one task's split under the protocol."""

    task: str
    """The task's name."""
    split: str
    """The split played."""
    returns: np.ndarray
    """[S] return per context (a stochastic controller's: the mean over its seeds)."""
    seed_means: np.ndarray
    """[seeds] mean return per controller seed (one entry for a deterministic one)."""
    cpu_seconds: float
    """Process CPU seconds of the controller's episodes (all threads, all seeds)."""

    @property
    def mean_return(self) -> float:
        return float(self.seed_means.mean())

    @property
    def standard_error(self) -> float:
        """The standard error of :attr:`mean_return` over the set's networks: the sample
        standard deviation of the per-context returns over sqrt(S) (NaN for one context).
        What a score on another draw of networks would move by, the scale any difference
        between two controllers on the suite is read against."""
        return standard_error(self.returns)


def standard_error(returns) -> float:
    """sd(returns) / sqrt(S) with the sample standard deviation (ddof 1), summed in a
    fixed order (math.fsum); NaN for fewer than two returns."""
    values = [float(value) for value in np.asarray(returns, dtype=np.float64).reshape(-1)]
    if len(values) < 2:
        return float("nan")
    mean = math.fsum(values) / len(values)
    variance = math.fsum((value - mean) ** 2 for value in values) / (len(values) - 1)
    return math.sqrt(variance / len(values))


def play(name: str, split: str, controller: Controller) -> tuple[np.ndarray, float]:
    """(returns [S], CPU seconds): ``controller`` on every context of the split once,
    with the task's extensions and the environment generator seeded with ENV_SEED."""
    contexts = load_split(name, split)
    started = time.process_time()
    episodes = evaluate_policy(
        contexts, controller, extensions=task(name).extensions, seed=ENV_SEED
    )
    return episodes.returns, time.process_time() - started


def score(name: str, split: str, make_controller, seeds: int = 1) -> Score:
    """Score ``make_controller(seed)`` (a controller for each of seeds 0 .. seeds - 1;
    seeds > 1 only for a stochastic controller) on a task's split."""
    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    played = [play(name, split, make_controller(seed)) for seed in range(seeds)]
    returns = np.stack([returns for returns, _ in played])
    return Score(name, split, returns.mean(axis=0), returns.mean(axis=1),
                 sum(seconds for _, seconds in played))  # fmt: skip


@functools.cache
def references(name: str, split: str = "test") -> tuple[float, float]:
    """(R_nothing, R_oracle): the mean returns of do nothing and of the oracle planner
    on a task's split under the protocol, the 0 and 1 of the normalised score."""
    from spikectl.envs.controller import DoNothing
    from spikectl.planning.oracle import DEFAULT_ORACLE_WIDTH, OraclePlanner

    contexts = load_split(name, split)
    nothing, _ = play(name, split, DoNothing())
    oracle = OraclePlanner(contexts, contexts.params, DEFAULT_ORACLE_WIDTH,
                           task(name).extensions.allow_target_action)  # fmt: skip
    planned, _ = play(name, split, oracle)
    return float(nothing.mean()), float(planned.mean())


def normalise(mean_return: float, nothing: float, oracle: float) -> float:
    """(R - R_nothing) / (R_oracle - R_nothing): 0 for doing nothing, 1 for the oracle."""
    if not oracle > nothing:
        raise ValueError(
            f"the oracle ({oracle:.6f}) does not beat doing nothing ({nothing:.6f}): "
            "no normalised score"
        )
    return (mean_return - nothing) / (oracle - nothing)


def mean_normalised(scores: dict[str, float]) -> float:
    """The suite's summary: the unweighted mean over tasks of each task's normalised score."""
    if not scores:
        raise ValueError("no task scores to average")
    return float(np.mean(list(scores.values())))


PER_NEURON_ARCHS = ("tdrqn", "ddrqn")
"""Architectures whose weights do not depend on n (shared per-neuron blocks)."""


def check_run_fits(config: Any, name: str) -> None:
    """Refuse a trained run (its saved config) that cannot play task ``name``: another
    neuron model or episode length, or a fixed-size network (DRQN, DMDRQN) trained on
    another number of observed neurons. A per-neuron network (TDRQN, DDRQN) plays any n."""
    spec = task(name)
    if config.env.params != NeuronParams():
        raise ValueError(
            f"the run was trained with other neuron parameters than task {name!r} (the "
            "suite's are the defaults, Table 1): its scores would be on another model"
        )
    if config.env.episode_length != EPISODE_LENGTH:
        raise ValueError(
            f"the run was trained on episodes of {config.env.episode_length} steps; the "
            f"suite's are {EPISODE_LENGTH}"
        )
    fixed_size = config.agent.arch.lower() not in PER_NEURON_ARCHS
    if fixed_size and config.env.n_observed != spec.n_observed:
        raise ValueError(
            f"a {config.agent.arch.upper()} has a fixed input of {config.env.n_observed} "
            f"observed neurons; task {name!r} shows {spec.n_observed}: only per-neuron "
            f"networks ({', '.join(a.upper() for a in PER_NEURON_ARCHS)}) run on another n"
        )


def trained_on(config: Any, train_set: ContextSet) -> str | None:
    """The suite task a run trained on (its saved config and training set), or None:
    the task whose n, extensions and pinned training-set checksum the run's match. The
    environment-level tasks share ``paper``'s networks, so the extensions decide."""
    checksum = suite_checksum(train_set)
    for name, spec in TASKS.items():
        if (
            config.env.n_neurons == spec.n_neurons
            and config.env.extensions == spec.extensions
            and checksum == CHECKSUMS[name]["train"]
        ):
            return name
    return None

