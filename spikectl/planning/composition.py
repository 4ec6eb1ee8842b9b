"""What an identify-and-plan controller is made of: four parts, each with its settings.

- the **estimator** (:mod:`~spikectl.planning.estimators`): which posterior over the
  connectivity it keeps, and when an entry counts as known;
- the **observation** model (:mod:`~spikectl.planning.observing`): how observations
  become evidence and the state the planner starts from (noise, filtering, stochastic
  release, heterogeneous neurons);
- the **decision** rule (:mod:`~spikectl.planning.deciding`): greedy beam re-planning,
  and QMDP where it would probe;
- the **prober** (:mod:`~spikectl.planning.probing`): what to stimulate to learn.

A :class:`Composition` is data with a name, so that a result can say what ran; the named
controller's compositions are in :mod:`~spikectl.planning.named`. A part's settings class
is also the part: a plug-in (``lab/planners``) subclasses one and overrides its rule.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from spikectl.planning.deciding import DecisionSettings
from spikectl.planning.estimators import EstimatorSettings
from spikectl.planning.observing import ObservationSettings
from spikectl.planning.probing import ProberSettings


@dataclass(frozen=True)
class Composition:
    """An identify-and-plan controller's parts. The defaults are the paper's model: the
    Gaussian estimate, spikes read at the threshold, greedy re-planning (width 32, 20
    steps ahead) and the probing rule.

    Attributes:
        name: what a result names as having run (``spikectl benchmark``'s
            ``composition`` column).
        estimator, observation, decision, prober: the parts.
    """

    name: str = "paper"
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings)
    observation: ObservationSettings = field(default_factory=ObservationSettings)
    decision: DecisionSettings = field(default_factory=DecisionSettings)
    prober: ProberSettings = field(default_factory=ProberSettings)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"a composition's name must be a non-empty string, got {self.name!r}")
        for part, kind in (("estimator", EstimatorSettings), ("observation", ObservationSettings),
                           ("decision", DecisionSettings), ("prober", ProberSettings)):  # fmt: skip
            if not isinstance(getattr(self, part), kind):
                raise TypeError(f"{part} must be a {kind.__name__}, got "
                                f"{type(getattr(self, part)).__name__}")  # fmt: skip

    def but(self, name: str, **parts: Any) -> Composition:
        """A copy named ``name`` with some parts replaced (``estimator=...``, ...)."""
        return dataclasses.replace(self, name=name, **parts)

    def with_width(self, width: int) -> Composition:
        """This composition re-planning at beam ``width`` (itself at its own width; else
        named ``NAME-widthW``)."""
        if width == self.decision.width:
            return self
        decision = dataclasses.replace(self.decision, width=width)
        return self.but(f"{self.name}-width{width}", decision=decision)
