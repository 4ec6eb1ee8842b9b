"""Model-based controllers that need no training: an oracle planner and identify-and-plan.

``plan_episode`` knows a context's weights and searches action sequences with the
batched simulator (the headroom of a network); ``IdentifyAndPlan`` knows only the neuron
model, estimates the connectivity from what it observes and plans on its estimate every
step. See docs/baselines.md. ``ObservedState``, ``FilteredState`` (measurement noise)
and ``NeuronTracker`` (heterogeneous neurons) are the trackers identify-and-plan reads
its observations with; ``RelayConnectivityEstimate`` is its estimate with the relays
through hidden neurons (the ``"relays"`` estimator); ``DiscreteConnectivityEstimate`` (n
<= 11) and ``ParticleConnectivityEstimate`` (any n) its posteriors over {-1, 0, +1}.
``IdentifyAndPlan`` is a ``Composition`` of parts (``EstimatorSettings``,
``ObservationSettings``, ``DecisionSettings`` with ``QMDPSettings``,
``ProberSettings``); ``named_composition`` gives the one the named ``identify-and-plan``
plays on an environment (``fast=True``: the form the guided learner's teacher plays)."""

from spikectl.planning.beam import Plan, PlanningModel, beam_search
from spikectl.planning.composition import Composition
from spikectl.planning.deciding import DecisionSettings
from spikectl.planning.discrete import DiscreteConnectivityEstimate
from spikectl.planning.estimators import ESTIMATORS, EstimatorSettings
from spikectl.planning.filtering import FilteredState
from spikectl.planning.heterogeneity import NeuronTracker
from spikectl.planning.identify import ConnectivityEstimate, ObservedState
from spikectl.planning.named import composition_name, named_composition
from spikectl.planning.observing import ObservationSettings
from spikectl.planning.oracle import (
    DEFAULT_ORACLE_WIDTH,
    OraclePlanner,
    model_of_context,
    plan_episode,
)
from spikectl.planning.particles import ParticleConnectivityEstimate
from spikectl.planning.policy import IdentifyAndPlan
from spikectl.planning.probing import ProberSettings
from spikectl.planning.qmdp import QMDPSettings
from spikectl.planning.relays import RelayConnectivityEstimate

__all__ = [
    "DEFAULT_ORACLE_WIDTH",
    "ESTIMATORS",
    "Composition",
    "ConnectivityEstimate",
    "DecisionSettings",
    "DiscreteConnectivityEstimate",
    "EstimatorSettings",
    "FilteredState",
    "IdentifyAndPlan",
    "NeuronTracker",
    "ObservationSettings",
    "ObservedState",
    "OraclePlanner",
    "Plan",
    "ParticleConnectivityEstimate",
    "PlanningModel",
    "ProberSettings",
    "QMDPSettings",
    "RelayConnectivityEstimate",
    "beam_search",
    "composition_name",
    "model_of_context",
    "named_composition",
    "plan_episode",
]
