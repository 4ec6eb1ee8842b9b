"""Recurrent Q-networks of the paper (Section 5.2): DRQN, DDRQN, DMDRQN, TDRQN.

Build one with :func:`make_agent`; see docs/agents.md for the architectures, the
input featurisation and the observation contract. Importing builds nothing.
"""

from spikectl.agents.blocks import (
    OBS_KEYS,
    greedy_action,
    masked_q,
    observation_batch,
    shift_pattern,
)
from spikectl.agents.networks import (
    AGENTS,
    ARCHITECTURES,
    DDRQN,
    DMDRQN,
    DRQN,
    TDRQN,
    AgentSizes,
    Architecture,
    RecurrentQNetwork,
    count_parameters,
    make_agent,
    make_voltage_predictor,
    parameter_counts,
    reset_state,
)

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
