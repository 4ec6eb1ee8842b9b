"""Recurrent Q-networks of the paper (Section 5.2): DRQN, DDRQN, DMDRQN, TDRQN.

Build one with :func:`make_agent`; see docs/agents.md for the architectures, the
input featurisation, the observation contract and which module holds what. Importing
builds nothing.
"""

from spikectl.agents.features import shift_pattern
from spikectl.agents.heads import greedy_action, masked_q
from spikectl.agents.networks import (
    AGENTS,
    count_parameters,
    make_agent,
    make_voltage_predictor,
    parameter_counts,
    reset_state,
)
from spikectl.agents.observation import OBS_KEYS, observation_batch
from spikectl.agents.per_neuron_networks import DDRQN, TDRQN
from spikectl.agents.recurrent import RecurrentQNetwork
from spikectl.agents.sizes import ARCHITECTURES, AgentSizes, Architecture
from spikectl.agents.system_networks import DMDRQN, DRQN

__all__ = [
    "AGENTS",
    "ARCHITECTURES",
    "DDRQN",
    "DMDRQN",
    "DRQN",
    "OBS_KEYS",
    "TDRQN",
    "AgentSizes",
    "Architecture",
    "RecurrentQNetwork",
    "count_parameters",
    "greedy_action",
    "make_agent",
    "make_voltage_predictor",
    "masked_q",
    "observation_batch",
    "parameter_counts",
    "reset_state",
    "shift_pattern",
]
