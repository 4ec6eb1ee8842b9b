"""Benchmark suite v1, frozen: the ten tasks its published scores were measured on.

Every task's sets are ``make_splits(100, 100, n, seed=0, extensions=..., n_val=100)``
(seed 0 for every task: the paper's sets, which every table of docs/baselines.md plays;
the environment-level variants play the very networks of ``paper``, so that their
differences are the variant's alone, and share its checksums).
"""

from __future__ import annotations

from spikectl.envs.registration import ENV_ID, VARIANTS
from spikectl.experiments.suite.versions import SuiteVersion, Task, register_suite_version
from spikectl.registry import Registry

_REALISTIC = VARIANTS.entry("spikectl/NeuronControlRealistic-v0")["extensions"]
"""The moderate strengths of the registered all-in-one variant, reused one at a time."""

_CHECKSUMS: dict[str, dict[str, str]] = {
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
"""task -> split -> suite checksum of the set (the environment-level variants share the
paper's networks, hence its checksums)."""


def _task(name, env_id, n, description, **overrides) -> Task:
    return Task(name, env_id, dict(overrides), n, 0, description, _CHECKSUMS[name])


def _tasks() -> Registry[Task]:
    tasks: Registry[Task] = Registry("task")
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
    ):  # fmt: skip
        tasks.register(task.name, task)
    return tasks


V1 = register_suite_version(SuiteVersion(1, frozen=True, tasks=_tasks()))
"""Suite v1 (``suite_version(1)``): its tasks in table order."""
