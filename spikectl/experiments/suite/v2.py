"""Benchmark suite v2: the loop a rig has, on 1 000 networks a set.

Suite v1 (:mod:`~spikectl.experiments.suite.v1`) stays frozen and reproducible as it was.
v2 plays the paper's model through what a real closed loop adds (docs/extensions.md):
loop latency (an action lands ``latency_steps`` steps after it is chosen) and an
optogenetic actuator. Its sets are ``make_splits(1000, 1000, 8, seed=2, n_val=1000)`` for
every task: 1 000 networks a set, so that a row's standard error over the networks is
about 0.004 (identify-and-plan's per-network sd on ``paper`` is 0.14), and a seed of
their own, so no v2 network is one of v1's. The environment-level tasks play the very
networks of ``paper`` (hence its checksums), so a task's row against ``paper``'s is the
cost of the loop alone.

``rig`` combines the loop's parts: ChR2 light, 2 steps of latency, spikes-only sensing and
spontaneous background input (0.005 inputs per neuron per step, v1's ``background``), which
stands for the rig's noise, since measurement noise acts on potentials that spikes-only
sensing does not report. v2 is not frozen: a task's scores do not move when another
task is added.
"""

from __future__ import annotations

from spikectl.envs.registration import ENV_ID
from spikectl.experiments.suite.versions import SuiteVersion, Task, register_suite_version
from spikectl.registry import Registry

SET_SIZE = 1000
"""Networks in each of a v2 task's train, validation and test sets."""
SEED = 2
"""The generation seed of every v2 task's sets."""

_N8_CHECKSUMS = {
    "train": "c4b061eb6e9712a52b65b5a9da646ddc8e95502bd83b40f716b96cc5872517fa",
    "validation": "7af720a101545f3e22e96de4f753017834906017e4da43feab1f5f2ccc5ed3be",
    "test": "c20dcbd2ed1999942002da0b82b9553128f113f5a4ec4509dd31e86b7782d80f",
}
"""The sets of every n = 8 task without context-level extensions (the paper's networks)."""


def _task(name: str, env_id: str, description: str, **overrides) -> Task:
    return Task(name, env_id, dict(overrides), 8, SEED, description, _N8_CHECKSUMS)


def _tasks() -> Registry[Task]:
    tasks: Registry[Task] = Registry("task")
    for task in (
        _task("paper", ENV_ID, "the paper's task, n = 8, on 1 000 networks a set"),
        _task("latency1", "spikectl/NeuronControlLatency1-v0",
              "an action lands 1 step (1 ms) after it is chosen"),
        _task("latency2", "spikectl/NeuronControlLatency2-v0",
              "an action lands 2 steps (2 ms) after it is chosen"),
        _task("spikes-only", "spikectl/NeuronControlSpikesOnly-v0",
              "the agent observes which neurons spiked, not their potentials"),
        _task("chr2", "spikectl/NeuronControlChR2-v0",
              "an action is a 1 ms light pulse on ChR2 (5 mW/mm^2), not the current pulse"),
        _task("rig", "spikectl/NeuronControlRig-v0",
              "the rig's loop: ChR2 light, 2 steps of latency, spikes only, background input"),
    ):  # fmt: skip
        tasks.register(task.name, task)
    return tasks


V2 = register_suite_version(SuiteVersion(2, set_size=SET_SIZE, tasks=_tasks()))
"""Suite v2 (``suite_version(2)``): its tasks in table order."""
