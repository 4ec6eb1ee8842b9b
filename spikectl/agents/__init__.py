"""Recurrent Q-networks of the paper (Section 5.2): DRQN, DDRQN, DMDRQN, TDRQN.

Build one with :func:`make_agent`; see docs/agents.md for the architectures, the
input featurisation, the observation contract and which module holds what. Importing
builds nothing, and imports nothing either until a name is first used: the package's
names load their modules (and so PyTorch) on first access, so that
:mod:`spikectl.agents.compiled` can load and run a trained policy on a machine without
importing PyTorch (docs/realtime.md).
"""

from __future__ import annotations

import importlib
from typing import Any

_HOMES = {
    "AGENTS": "networks",
    "ARCHITECTURES": "sizes",
    "CompiledPolicy": "compiled",
    "DDRQN": "per_neuron_networks",
    "DMDRQN": "system_networks",
    "DRQN": "system_networks",
    "GreedyController": "greedy",
    "INPUT_FEATURES": "inputs",
    "InputFeature": "inputs",
    "OBS_KEYS": "observation",
    "TDRQN": "per_neuron_networks",
    "AgentSizes": "sizes",
    "Architecture": "sizes",
    "RecurrentQNetwork": "recurrent",
    "count_parameters": "networks",
    "export_policy": "compiled",
    "greedy_action": "heads",
    "make_agent": "networks",
    "make_connectivity_predictor": "networks",
    "make_voltage_predictor": "networks",
    "masked_q": "heads",
    "observation_batch": "observation",
    "parameter_counts": "networks",
    "reset_state": "networks",
    "shift_pattern": "features",
}
"""Each public name → the module of this package that defines it."""

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    # PEP 562: load the defining module on first use (``from spikectl.agents import x``
    # comes here too), then keep the name so later lookups skip this function.
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'spikectl.agents' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"spikectl.agents.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOMES))
