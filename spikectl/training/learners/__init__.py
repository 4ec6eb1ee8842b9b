"""The learners of the training loop, chosen by name (``config.learner``).

A learner is the algorithm inside the run (``spikectl.training.run``): it acts on batches
of observations while episodes are collected, takes the finished episodes, updates its
networks and gives and takes its whole state for checkpoints (:class:`Learner`). Each
learner is one module and one config class; adding one means adding both here.

=========  =========================  ==============================================
name       config                     learner
=========  =========================  ==============================================
``dqn``    :class:`DQNConfig`         recurrent double Q-learning (the paper's)
``guided`` :class:`GuidedConfig`      the same, guided by a teacher (DAgger + DQfD)
``pqn``    :class:`PQNConfig`         parallel Q(lambda) without replay or target network
=========  =========================  ==============================================
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Union

from spikectl.training.learners.dqn_config import DQNConfig
from spikectl.training.learners.guided_config import GuidedConfig
from spikectl.training.learners.pqn_config import PQNConfig

if TYPE_CHECKING:
    from spikectl.training.learners.protocol import Learner, LearnerGroup

LearnerConfig = Union[DQNConfig, GuidedConfig, PQNConfig]  # noqa: UP007 (tyro reads the Union)
"""The type of ``Experiment.learner``: the union of every learner's config. On the
command line the preset chooses the learner and its flags are that learner's
(``spikectl train guided --teacher identify``)."""

LEARNER_CONFIGS: dict[str, type] = {
    config.name: config for config in (DQNConfig, GuidedConfig, PQNConfig)
}
"""Every learner's config class by its name in config.json."""


def learner_config_type(name: object) -> type:
    """The config class of the learner called ``name``; a clear error for another name."""
    if name not in LEARNER_CONFIGS:
        raise ValueError(
            f"learner.name: unknown learner {name!r}; this spikectl has "
            f"{', '.join(sorted(LEARNER_CONFIGS))}"
        )
    return LEARNER_CONFIGS[name]


def make_learner(config, train_set, rng) -> Learner:
    """The learner of ``config.learner`` for one seed: it draws from the run's ``rng``."""
    from spikectl.training.learners.dqn import DQNLearner
    from spikectl.training.learners.guided import GuidedDQNLearner
    from spikectl.training.learners.pqn import PQNLearner

    implementations = {DQNConfig: DQNLearner, GuidedConfig: GuidedDQNLearner, PQNConfig: PQNLearner}
    return implementations[type(config.learner)](config, train_set, rng)


STACKED_GROUPS = (DQNConfig,)
"""The learners whose seeds can also train as one stacked computation (``--stacked``)."""


def check_stacked(configs) -> None:
    """Refuse ``--stacked`` for a learner that has no stacked form (before a run starts)."""
    if type(configs[0].learner) not in STACKED_GROUPS:
        raise ValueError(
            f"--stacked: the {configs[0].learner.name} learner has no stacked form "
            "(drop --stacked: a group of seeds loops, each seed exactly as alone)"
        )


def make_learners(configs, train_sets, rngs, stacked: bool = False) -> LearnerGroup:
    """The learners of K seeds (one per config, training set and generator) as the
    group the loop drives: looped (each seed exactly as alone) or, with ``stacked``,
    one stacked computation where the learner has one."""
    if stacked:
        check_stacked(configs)
        from spikectl.training.learners.dqn_stacked import StackedDQN

        return StackedDQN(configs, train_sets, rngs)
    from spikectl.training.learners.looped import LoopedLearners

    return LoopedLearners(
        [make_learner(c, s, r) for c, s, r in zip(configs, train_sets, rngs, strict=True)]
    )


__all__ = ["DQNConfig", "GuidedConfig", "LEARNER_CONFIGS", "LearnerConfig", "PQNConfig",
           "check_stacked", "learner_config_type", "make_learner", "make_learners"]  # fmt: skip
