"""The settings of teacher-guided recurrent double Q-learning
(``spikectl.training.learners.guided``): the DQN learner's, plus the teacher's.

A plain frozen dataclass with no Torch in sight (like :class:`DQNConfig`, which it
extends: every DQN option keeps its meaning).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from spikectl.config_errors import ConfigError
from spikectl.training.learners.dqn_config import DQNConfig
from spikectl.training.learners.registry import Preset

TEACHERS = ("identify", "told-weights", "oracle")
"""``identify``: identify-and-plan, which sees only what the agent sees (realisable);
``told-weights``: the same loop told the network's true weights (privileged: a student
cannot copy what it cannot infer, the imitation gap; docs/training.md); ``oracle``: the
oracle planner's open-loop plan of the played network (privileged; it plans for the
loop's latency and actuator and reads nothing of the episode, so it teaches where no
loop that identifies can play, e.g. the rig's loop)."""


@dataclass(frozen=True)
class GuidedConfig(DQNConfig):
    """Recurrent double Q-learning guided by a teacher: DAgger-style relabelling of the
    agent's own episodes with a large-margin imitation loss (DQfD), weaned off."""

    name: ClassVar[str] = "guided"
    """The learner's name in config.json (``"learner": {"name": "guided", ...}``)."""

    teacher: Literal["identify", "told-weights", "oracle"] = "identify"
    """Who labels the visited states: identify-and-plan, the same loop told the weights,
    or the oracle planner's open-loop plan of the played network."""
    teacher_width: int = 32
    """Beam width of the teacher's plans (identify-and-plan's default; the oracle's too,
    in place of its reference width 256, whose plan of a network costs 8 times more)."""
    teacher_settings: Literal["task", "defaults"] = "task"
    """The ``identify`` teacher's other settings. ``task``: those the named
    ``identify-and-plan`` plays on the training environment, in the form whose every
    decision is fast (``named_composition(..., fast=True)``: the task's observation
    model under noise, the extensions, the relays through hidden neurons; from 16 neurons
    on ``known_sd`` 0.4 and no QMDP). ``defaults``: the constructor's defaults on every
    environment (the teacher of the runs saved before this setting existed). On the
    paper's task the two are the same."""
    imitation_weight: float = 1.0
    """Weight of the large-margin imitation loss at the start of training."""
    imitation_weight_end: float = 0.0
    """Weight at the end of the anneal, then constant; at 0 the teacher stops labelling."""
    imitation_anneal_fraction: float = 0.5
    """Fraction of all episodes over which the weight moves linearly to its end value."""
    imitation_margin: float = 0.05
    """Margin (in units of return) by which the teacher's action should lead every other."""
    teacher_episodes: float = 0.0
    """Share of the episodes the teacher plays itself at the start (DAgger's mixing),
    decaying linearly to 0 over the imitation anneal; its episodes are labelled for free."""
    connectivity_weight: float = 0.0
    """Weight of an auxiliary loss asking the features to say, at every step, each observed
    neuron's synapse onto the target, labelled from the training networks' weights
    (privileged, read only by the loss; 0 = off)."""

    removed_fields: ClassVar[dict[str, tuple[Any, str]]] = {
        "asymmetric_critic": (
            False,
            "the privileged critic measured no change, docs/results/asymmetric-critic",
        ),
    }
    """Fields of earlier versions' configs, with the value under which a run ran as
    today's (read by ``Experiment.from_dict``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.teacher_width < 1:
            raise ConfigError(
                "teacher_width", f"must be a positive integer, got {self.teacher_width}"
            )
        for name in ("imitation_weight", "imitation_weight_end", "imitation_anneal_fraction",
                     "imitation_margin", "teacher_episodes", "connectivity_weight"):  # fmt: skip
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(name, f"must be a finite number >= 0, got {value!r}")
        for name in ("imitation_anneal_fraction", "teacher_episodes"):
            if getattr(self, name) > 1:
                raise ConfigError(name, f"must lie in [0, 1], got {getattr(self, name)}")
        if self.teacher_episodes > 0 and self.teacher != "identify":
            raise ConfigError(
                "teacher_episodes",
                f"only teacher 'identify' can play episodes itself, not {self.teacher!r} "
                "(set teacher_episodes to 0)",
            )

    @classmethod
    def fields_saved_without(cls, env: Any) -> dict[str, Any]:
        """The values of fields a config saved before they existed lacks, as its run had
        them on the environment ``env`` (an ``EnvConfig``): ``teacher_settings`` was the
        constructor's defaults, which are the task's own where the two are the same (the
        paper's environment), so those runs read back as today's preset."""
        from spikectl.planning.named import composition_name

        same = composition_name(env.extensions, env.n_observed, fast=True) == "paper"
        return {"teacher_settings": "task" if same else "defaults"}

    @property
    def teaches(self) -> bool:
        """Whether the teacher labels or plays any episode: an imitation weight or a
        teacher's share above 0 at some point of the run."""
        if self.imitation_weight_end > 0:
            return True
        return self.imitation_anneal_fraction > 0 and (
            self.imitation_weight > 0 or self.teacher_episodes > 0
        )

    def teacher_share_at(self, episode: int, total_episodes: int) -> float:
        """The share of episodes the teacher plays after ``episode`` episodes: linear from
        teacher_episodes to 0 over the imitation anneal (0 without an anneal)."""
        anneal = self.imitation_anneal_fraction * total_episodes
        if anneal <= 0 or self.teacher_episodes <= 0:
            return 0.0
        return self.teacher_episodes * max(1.0 - episode / anneal, 0.0)

    def imitation_weight_at(self, episode: int, total_episodes: int) -> float:
        """The imitation loss's weight after ``episode`` episodes: linear from
        imitation_weight to imitation_weight_end over the anneal, then constant."""
        anneal = self.imitation_anneal_fraction * total_episodes
        if anneal <= 0:
            return self.imitation_weight_end
        fraction = min(episode / anneal, 1.0)
        return self.imitation_weight + fraction * (
            self.imitation_weight_end - self.imitation_weight
        )


def guided_preset(presets: Mapping[str, Any]) -> Any:
    """The README's main job: the quick preset's run and sizes with the teacher-guided
    learner (docs/training.md, "Teacher-guided learning"): identify-and-plan labels the
    states the agent visits; the imitation weight falls from 1 to a floor of 0.2 over the
    first half of the episodes and stays there; a privileged auxiliary loss of weight 0.1
    asks the features for each neuron's synapse onto the target; 24 updates a round (6 600
    in all); 1 000 training networks, so the 4 400 episodes see each network about 4
    times. Each choice was made on the validation networks; the measurements are in the
    research record (docs/research/index.md). The test and validation sets are the same
    100 networks whatever ``n_train`` is (``make_splits``)."""
    quick = presets["quick"]
    return dataclasses.replace(
        quick,
        env=dataclasses.replace(quick.env, n_train=1000),
        learner=GuidedConfig(
            **{**dataclasses.asdict(quick.learner), "updates_per_round": 24},
            teacher="identify",
            imitation_weight_end=0.2,
            connectivity_weight=0.1,
        ),
    )


PRESETS = (
    Preset(
        "guided",
        "The main job: quick on 1 000 networks, taught by identify-and-plan (floor 0.2).",
        guided_preset,
    ),
)
"""The learner's presets (``spikectl train guided``)."""
