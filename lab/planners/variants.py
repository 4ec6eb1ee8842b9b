"""Identify-and-plan's parts the research record measured no gain in, as plug-ins.

Each subclasses a core part's settings (:mod:`spikectl.planning`) and overrides its rule;
a :class:`~spikectl.planning.Composition` takes it where it takes the core part:

```python
from lab.planners import PosteriorSample
from spikectl.planning import Composition, IdentifyAndPlan

policy = IdentifyAndPlan(composition=Composition("thompson",
                                                 decision=PosteriorSample(samples=64)))
```
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl import NeuronParams
from spikectl.planning import (
    DecisionSettings,
    DiscreteConnectivityEstimate,
    ObservationSettings,
    PlanningModel,
)
from spikectl.planning.deciding import Situation


def discrete(n: int, residual_sd: float, model, params: NeuronParams):
    """The ``"discrete"`` estimator (an :data:`~spikectl.planning.estimators.EstimateFactory`;
    ``model``, the task's observation model, is not read): the exact posterior over
    {-1, 0, +1} under the paper's model (n <= 11). It knows more entries than the Gaussian
    estimate (55 vs 48 of 64 at the end of a training episode) but did not plan better
    (-0.010 on the training networks, docs/research/identify-and-plan.md); the core's
    ``"bayes"`` is the same posterior under the task's observation model."""
    return DiscreteConnectivityEstimate(n, residual_sd)


def _check_count(name: str, value) -> None:
    """Refuse anything but an integer >= 1 (ValueError naming ``name``)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


@dataclass(frozen=True)
class PosteriorSample(DecisionSettings):
    """Thompson sampling: each re-plan plans on one network drawn from the estimate (the
    re-plan's own draw of the episode's uniforms, the i-th re-plan the i-th draw modulo
    ``samples``), so that a plan sometimes stimulates what the estimate doubts. Under
    spikes-only sensing it was within noise of the ``spikes`` composition without QMDP
    on two sets of validation networks (docs/results/iap-spikes)."""

    samples: int = 64

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_count("samples", self.samples)

    @property
    def draws(self) -> int:
        return max(self.samples, super().draws)

    def planning_model(self, policy, weights: np.ndarray, situation: Situation) -> PlanningModel:
        k = policy.replans % self.samples
        uniforms = (policy.uniforms[0][k : k + 1], policy.uniforms[1][k : k + 1])
        drawn = policy.estimate.sample(policy.known_sd, *uniforms)  # [1, n, n]
        return PlanningModel(drawn, situation.target, situation.actions, policy.params,
                             policy.planned_neurons())  # fmt: skip


@dataclass(frozen=True)
class ReleaseChanceEvidence(ObservationSettings):
    """Under stochastic release, each spike enters the Gaussian estimate at its release
    chance, never settled from the residuals: what the named controller played before
    release settling (0.675 against 0.688 on the ``stochastic`` train and validation
    sets, docs/results/release-settling)."""

    def settles_releases(self, extensions, noise_mV: float) -> bool:
        return False


@dataclass(frozen=True)
class PlanUnderRelease(DecisionSettings):
    """Under stochastic release, the plan's own action where it misses the next wanted
    spike (no unrested input stimulated): what the named controller played before
    (-0.008 network by network on the ``stochastic`` sets, docs/results/unrested-inputs)."""

    def under_release(self, policy, weights, known, situation, action: int) -> int:
        return action
