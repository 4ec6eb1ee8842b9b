"""The benchmark suite (docs/benchmark.md): versions of frozen tasks, their context sets
pinned by checksum, one evaluation protocol and the normalised score.

Each task is a registered environment (``spikectl/NeuronControl-v0`` or one of its
variants, with a few settings changed) and a network size. A suite version is data
(:mod:`~spikectl.experiments.suite.versions`): its tasks, set size, episode length,
environment seed and the checksums of its sets. Version 1
(:mod:`~spikectl.experiments.suite.v1`) is frozen; v2
(:mod:`~spikectl.experiments.suite.v2`, the rig's loop on 1 000 networks a set) lives
beside it, and another version would too,
registered with :func:`register_suite_version` and given its tasks with
:func:`register_task`. The protocol (:mod:`~spikectl.experiments.suite.protocol`) and
the runs' side (:mod:`~spikectl.experiments.suite.runs`) take the task's name and the
version (default 1).
"""

from spikectl.experiments.suite import v1 as _v1  # noqa: F401  (registers suite v1)
from spikectl.experiments.suite import v2 as _v2  # noqa: F401  (registers suite v2)
from spikectl.experiments.suite.protocol import (
    Score,
    SuiteChecksumError,
    generate_splits,
    load_split,
    load_splits,
    mean_normalised,
    normalise,
    play,
    reference_scores,
    references,
    score,
    standard_error,
    suite_checksum,
)
from spikectl.experiments.suite.runs import (
    PER_NEURON_ARCHS,
    check_run_fits,
    train_arguments,
    trained_on,
)
from spikectl.experiments.suite.versions import (
    DEFAULT_SUITE,
    SPLITS,
    SUITES,
    SuiteVersion,
    Task,
    register_suite_version,
    register_task,
    suite_version,
    task,
)

__all__ = [
    "DEFAULT_SUITE", "PER_NEURON_ARCHS", "SPLITS", "SUITES", "Score", "SuiteChecksumError",
    "SuiteVersion", "Task", "check_run_fits", "generate_splits", "load_split", "load_splits",
    "mean_normalised", "normalise", "play", "reference_scores", "references",
    "register_suite_version", "register_task", "score", "standard_error", "suite_checksum",
    "suite_version", "task", "train_arguments", "trained_on",
]  # fmt: skip
