"""The learners of the training loop, chosen by name (``config.learner``).

A learner is the algorithm inside the run (``spikectl.training.run``): it acts on batches
of observations while episodes are collected, takes the finished episodes, updates its
networks and gives and takes its whole state for checkpoints (:class:`Learner`).

=========  =========================  ==============================================
name       config                     learner
=========  =========================  ==============================================
``dqn``    :class:`DQNConfig`         recurrent double Q-learning (the paper's)
``guided`` :class:`GuidedConfig`      the same, guided by a teacher (DAgger + DQfD)
``pqn``    :class:`PQNConfig`         parallel Q(lambda) without replay or target network
=========  =========================  ==============================================

How to add a learner (three files of spikectl, nothing outside this package):

1. ``NAME_config.py``: a frozen dataclass with ``name: ClassVar[str] = "NAME"``, a
   docstring per field, ``__post_init__`` checking values (``check_field_types`` first) and
   ``check_episode_length(episode_length)`` (and, where it builds on the agent's network,
   ``check_agent(arch, sizes)``, which the config tree calls); beside it, its presets
   (``PRESETS = (Preset("NAME", "one line of help", build),)``, ``build`` making the
   Experiment from the base presets). A Q-learner takes its epsilon and learning-rate
   settings from :class:`~spikectl.training.learners.q_settings.QSettings`.
2. ``NAME.py``: the learner (:class:`~spikectl.training.learners.protocol.Learner`), made
   as ``Learner(config, train_set, rng)``; a Q-learner builds on
   :mod:`~spikectl.training.learners.q_learning`. A learner that cannot train on some
   environments refuses them in a classmethod ``check_environment(config)`` (raising a
   ConfigError), which the loop calls before any directory is made.
3. One ``register(...)`` line below. The config tree (``Experiment.learner``,
   config.json), the loop, the presets, ``spikectl train NAME``, sweeps and checkpoints
   then know it; add its row to the table above.

Tests register a learner the same public way (tests/test_learner_protocol.py).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Union

from spikectl.training.learners import guided_config, pqn_config
from spikectl.training.learners.dqn_config import DQNConfig
from spikectl.training.learners.guided_config import GuidedConfig
from spikectl.training.learners.pqn_config import PQNConfig
from spikectl.training.learners.registry import (
    LearnerEntry,
    Preset,
    learner_config_type,
    learner_configs,
    learner_entries,
    learner_entry,
    register,
)

if TYPE_CHECKING:
    from spikectl.training.learners.protocol import Learner, LearnerGroup

_HERE = "spikectl.training.learners"
register(DQNConfig, f"{_HERE}.dqn:DQNLearner", stacked=f"{_HERE}.dqn_stacked:StackedDQN")
register(GuidedConfig, f"{_HERE}.guided:GuidedDQNLearner", presets=guided_config.PRESETS)
register(PQNConfig, f"{_HERE}.pqn:PQNLearner", presets=pqn_config.PRESETS)

LearnerConfig = Union[learner_configs()]  # noqa: UP007 (tyro reads the Union)
"""The type of ``Experiment.learner`` on the command line: the union of the learners'
configs registered with spikectl. The preset chooses the learner and its flags are that
learner's (``spikectl train guided --teacher identify``)."""


def entry_of(config) -> LearnerEntry:
    """The registry entry of ``config.learner`` (an Experiment's)."""
    entry = learner_entry(type(config.learner).name)
    if entry.config is not type(config.learner):
        raise TypeError(f"{type(config.learner).__name__} is not the registered {entry.name}")
    return entry


def make_learner(config, train_set, rng) -> Learner:
    """The learner of ``config.learner`` for one seed: it draws from the run's ``rng``."""
    return entry_of(config).learner_class()(config, train_set, rng)


def check_stacked(configs) -> None:
    """Refuse ``--stacked`` for a learner that has no stacked form (before a run starts)."""
    if entry_of(configs[0]).stacked is None:
        raise ValueError(
            f"--stacked: the {configs[0].learner.name} learner has no stacked form "
            "(drop --stacked: a group of seeds loops, each seed exactly as alone)"
        )


def check_environment(configs) -> None:
    """Refuse, before a run starts, a learner that cannot train on its environment: the
    learner class's ``check_environment(config)`` where it has one (the guided learner's
    refuses a teacher that cannot play the environment). The configs of a group differ
    only in seed and training-set size, so the first speaks for all."""
    check = getattr(entry_of(configs[0]).learner_class(), "check_environment", None)
    if check is not None:
        check(configs[0])


def make_learners(configs, train_sets, rngs, stacked: bool = False) -> LearnerGroup:
    """The learners of K seeds (one per config, training set and generator) as the
    group the loop drives: looped (each seed exactly as alone) or, with ``stacked``,
    one stacked computation where the learner has one."""
    if stacked:
        check_stacked(configs)
        return entry_of(configs[0]).stacked_class()(configs, train_sets, rngs)
    from spikectl.training.learners.looped import LoopedLearners

    return LoopedLearners(
        [make_learner(c, s, r) for c, s, r in zip(configs, train_sets, rngs, strict=True)]
    )


__all__ = ["DQNConfig", "GuidedConfig", "LearnerConfig", "LearnerEntry", "PQNConfig", "Preset",
           "check_environment", "check_stacked", "entry_of", "learner_config_type",
           "learner_configs", "learner_entries", "learner_entry", "make_learner",
           "make_learners", "register"]  # fmt: skip
