"""Trained runs and the suite: the ``spikectl train`` flags of a task, whether a run can
play a task, and which task a run trained on."""

from __future__ import annotations

from typing import Any

from spikectl.contexts import ContextSet
from spikectl.experiments.suite.protocol import suite_checksum
from spikectl.experiments.suite.versions import DEFAULT_SUITE, suite_version, task
from spikectl.neuron.params import NeuronParams

PER_NEURON_ARCHS = ("tdrqn", "ddrqn")
"""Architectures whose weights do not depend on n (shared per-neuron blocks)."""


def train_arguments(name: str, version: int = DEFAULT_SUITE) -> list[str]:
    """The ``spikectl train`` flags that train on task ``name``: its environment, n,
    extension overrides and its sets' sizes and seed, so that the run's training and
    validation sets are the task's (tested) whatever the preset's own sizes (the guided
    preset trains on 1 000 networks)."""
    suite, spec = suite_version(version), task(name, version)
    arguments = ["--env", spec.env_id, "--n-neurons", str(spec.n_neurons),
                 "--episode-length", str(suite.episode_length)]  # fmt: skip
    for flag in ("--n-train", "--n-test", "--n-val"):
        arguments += [flag, str(suite.set_size)]
    arguments += ["--context-seed", str(spec.seed)]
    for field_name, value in spec.overrides.items():
        flag = "--extensions." + field_name.replace("_", "-")
        if isinstance(value, bool):
            arguments.append(flag if value else flag.replace("--extensions.", "--extensions.no-"))
        else:
            arguments += [flag, repr(value)]
    return arguments


def check_run_fits(config: Any, name: str, version: int = DEFAULT_SUITE) -> None:
    """Refuse a trained run (its saved config) that cannot play task ``name``: another
    neuron model or episode length, or a fixed-size network (DRQN, DMDRQN) trained on
    another number of observed neurons. A per-neuron network (TDRQN, DDRQN) plays any n."""
    suite, spec = suite_version(version), task(name, version)
    if config.env.params != NeuronParams():
        raise ValueError(
            f"the run was trained with other neuron parameters than task {name!r} (the "
            "suite's are the defaults, Table 1): its scores would be on another model"
        )
    if config.env.episode_length != suite.episode_length:
        raise ValueError(
            f"the run was trained on episodes of {config.env.episode_length} steps; the "
            f"suite's are {suite.episode_length}"
        )
    fixed_size = config.agent.arch.lower() not in PER_NEURON_ARCHS
    if fixed_size and config.env.n_observed != spec.n_observed:
        raise ValueError(
            f"a {config.agent.arch.upper()} has a fixed input of {config.env.n_observed} "
            f"observed neurons; task {name!r} shows {spec.n_observed}: only per-neuron "
            f"networks ({', '.join(a.upper() for a in PER_NEURON_ARCHS)}) run on another n"
        )


def trained_on(config: Any, train_set: ContextSet, version: int = DEFAULT_SUITE) -> str | None:
    """The task of suite ``version`` a run trained on (its saved config and training
    set), or None: the task whose n, extensions and pinned training-set checksum the
    run's match. The environment-level tasks share ``paper``'s networks, so the
    extensions decide."""
    checksum = suite_checksum(train_set)
    suite = suite_version(version)
    for name in suite.names():
        spec = suite.task(name)
        if (
            config.env.n_neurons == spec.n_neurons
            and config.env.extensions == spec.extensions
            and checksum == spec.checksums["train"]
        ):
            return name
    return None
