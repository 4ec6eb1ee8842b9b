"""Research-only parts of identify-and-plan: variants the research record measured and
found no gain in, kept as plug-ins on the core's public parts so that the record's
scripts still reproduce their rows (lab/planners/README.md lists each with its
measurement). Importing this package registers the ``"discrete"`` estimator in
:data:`spikectl.planning.ESTIMATORS`."""

from lab.planners.target_paths import TargetPathsOnly, target_ancestors
from lab.planners.variants import (
    PlanUnderRelease,
    PosteriorSample,
    ReleaseChanceEvidence,
    discrete,
)
from spikectl.planning import ESTIMATORS

ESTIMATORS.register("discrete", discrete)

__all__ = [
    "PlanUnderRelease",
    "PosteriorSample",
    "ReleaseChanceEvidence",
    "TargetPathsOnly",
    "discrete",
    "target_ancestors",
]
