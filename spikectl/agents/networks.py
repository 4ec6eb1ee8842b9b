"""The paper's four recurrent Q-networks by name (Section 5.2, App. C and D;
docs/agents.md): :func:`make_agent` builds one, and the helpers around it.

- :class:`DRQN`   one LSTM over the whole system, + context → FF → n+1 Q-values.
- :class:`DDRQN`  one shared LSTM with a state per neuron → per-neuron FF, + context
  → per-neuron Q-values; permutation equivariant, any n.
- :class:`DMDRQN` per-neuron LSTM states concatenated across neurons → FF, + context
  → n+1 Q-values; fixed n, not equivariant.
- :class:`TDRQN`  per-neuron LSTM states → transformer across neurons, + context →
  per-neuron Q-values; permutation equivariant, any n.

The fixed-n pair lives in :mod:`spikectl.agents.system_networks`, the equivariant pair
in :mod:`spikectl.agents.per_neuron_networks`, what all four share in
:mod:`spikectl.agents.recurrent` and their sizes in :mod:`spikectl.agents.sizes`; all
are importable from here too, as they were when this module held them. Q-vectors are
ordered by action + 1 (index 0 = do nothing).
"""

from __future__ import annotations

from dataclasses import fields, replace

import torch
from torch import nn

from spikectl.agents.heads import ConnectivityPredictor, NextVoltagePredictor
from spikectl.agents.per_neuron_networks import DDRQN, TDRQN
from spikectl.agents.per_neuron_networks import PerNeuronQNetwork as PerNeuronQNetwork
from spikectl.agents.recurrent import Observation as Observation
from spikectl.agents.recurrent import RecurrentQNetwork as RecurrentQNetwork
from spikectl.agents.recurrent import State
from spikectl.agents.recurrent import voltage_range as voltage_range
from spikectl.agents.sizes import ARCHITECTURES, INPUT_FLAGS, AgentSizes
from spikectl.agents.sizes import Architecture as Architecture
from spikectl.agents.system_networks import DMDRQN, DRQN
from spikectl.neuron.params import NeuronParams

AGENTS: dict[str, type[nn.Module]] = dict(
    zip(ARCHITECTURES, (DRQN, DDRQN, DMDRQN, TDRQN), strict=True)
)
"""Architecture name → class."""


def make_agent(
    name: str,
    n_neurons: int,
    episode_length: int,
    sizes: AgentSizes | None = None,
    params: NeuronParams | None = None,
    **overrides: object,
) -> nn.Module:
    """Build one of the four networks by name (drqn, ddrqn, dmdrqn, tdrqn).

    ``sizes`` defaults to Table 2 (:class:`AgentSizes`); keyword overrides replace
    single fields, e.g. ``make_agent("tdrqn", 8, 60, lstm_hidden=64)``. ``params`` are
    the environment's model parameters (default: Table 1): their V_r and V_th normalise
    the voltage input.
    """
    key = name.lower() if isinstance(name, str) else name
    if key not in AGENTS:
        raise ValueError(f"unknown agent {name!r}; choose one of {sorted(AGENTS)}")
    valid = {f.name for f in fields(AgentSizes)}
    unknown = sorted(set(overrides) - valid)
    flags = {name: feature for name, feature, _ in INPUT_FLAGS}
    for name in unknown:
        if name in flags:
            raise TypeError(f"make_agent: {name} is now inputs=(...), the input features' "
                            f"names in order (its feature: {flags[name]!r})")  # fmt: skip
    if unknown:
        raise TypeError(f"make_agent: unknown size fields {unknown}; valid fields: {sorted(valid)}")
    sizes = replace(sizes or AgentSizes(), **overrides)
    sizes.check_architecture(key)
    return AGENTS[key](n_neurons, episode_length, sizes, params)


def make_voltage_predictor(network: nn.Module) -> NextVoltagePredictor:
    """The auxiliary next-voltage head that reads ``network.encode``'s features."""
    n_fixed = None if network.equivariant else network.n_neurons
    return NextVoltagePredictor(network.feature_width, n_fixed)


def make_connectivity_predictor(network: nn.Module) -> ConnectivityPredictor:
    """The auxiliary head that reads ``network.encode``'s features and says each observed
    neuron's synapse onto the target (the guided learner's ``connectivity_weight``)."""
    n_fixed = None if network.equivariant else network.n_neurons
    return ConnectivityPredictor(network.feature_width, n_fixed)


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


def parameter_counts(
    n_neurons: int = 8, episode_length: int = 60, sizes: AgentSizes | None = None
) -> dict[str, int]:
    """Trainable parameters of each architecture (default: Table 2 sizes, n = 8, N = 60)."""
    return {
        name: count_parameters(make_agent(name, n_neurons, episode_length, sizes))
        for name in AGENTS
    }


def reset_state(state: State, done: torch.Tensor) -> State:
    """Zero the hidden state of the batch rows where ``done`` [B] (bool) is True.

    Every state tensor has the batch first, so this serves all four networks
    (e.g. when some of several parallel episodes restart).
    """
    return tuple(
        s.masked_fill(done.reshape(-1, *([1] * (s.dim() - 1))), 0.0)  # [B, ...]
        for s in state
    )
