"""The per-neuron input features a network may read besides the paper's two, each
registered under a name: ``AgentSizes.inputs`` lists the names, in order.

Every per-neuron network (DDRQN, DMDRQN, TDRQN) feeds its shared LSTM, for each neuron,
the neuron's normalised voltage and whether it was stimulated at t-1 (the paper's
input), then the columns of the features ``AgentSizes.inputs`` names, in that order.
A feature is an :class:`InputFeature`: its width per neuron and a pure function from
the observation tensors to its columns. Adding one is a module that defines it and one
``INPUT_FEATURES.register(...)`` line (the public way; ``"module:attribute"`` strings
are imported only when a network first needs them):

```python
from spikectl.agents.inputs import INPUT_FEATURES, InputFeature

def step_fraction(obs, voltage, dtype):  # [..., n, 1]: how far the episode has run
    fraction = obs["step"].to(dtype) / obs["pattern"].shape[-1]  # [...]
    return fraction[..., None, None].expand(*voltage.shape, 1)

INPUT_FEATURES.register("step-fraction", InputFeature(1, step_fraction, "t / N"))
```

DRQN reads the system's voltages and last action instead (``features.system_features``):
it ignores the features that predate this registry (``drqn_ignores``, so that a preset
carries them to every architecture) and refuses the others.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import torch

from spikectl.agents.features import (
    neuron_indicator,
    neuron_positions,
    normalised_voltage,
    target_proximity,
)
from spikectl.agents.spikes import VISIBLE_SPIKE_LEVEL
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.neuron.extensions import MAX_LATENCY_STEPS
from spikectl.registry import Registry

FeatureFunction = Callable[[Mapping[str, torch.Tensor], torch.Tensor, torch.dtype], torch.Tensor]
"""``(obs, voltage, dtype) -> [..., n, width]``: ``obs`` the observation tensors (leading
``[B, T]`` or ``[B]``), ``voltage`` [..., n] each neuron's normalised voltage
(:func:`~spikectl.agents.features.normalised_voltage`), ``dtype`` the network's."""


@dataclass(frozen=True)
class InputFeature:
    """One per-neuron input feature: ``width`` columns per neuron, computed by ``compute``
    from what the agent observes."""

    width: int
    """Columns per neuron."""
    compute: FeatureFunction
    """Its columns [..., n, width] from the observation tensors (:data:`FeatureFunction`)."""
    description: str
    """One line for docs and messages."""
    drqn_ignores: bool = False
    """DRQN, which reads no per-neuron input, ignores it instead of refusing it."""

    def __post_init__(self) -> None:
        if isinstance(self.width, bool) or not isinstance(self.width, int) or self.width < 1:
            raise ValueError(f"an input feature's width must be an int >= 1, got {self.width!r}")
        if not callable(self.compute):
            raise TypeError(f"an input feature's compute must be callable, got {self.compute!r}")


INPUT_FEATURES: Registry[InputFeature] = Registry("input feature")
"""The registered per-neuron input features, by name (``AgentSizes.inputs``)."""


def input_feature(name: str) -> InputFeature:
    """The feature registered under ``name`` (a one-line ``RegistryError`` naming the
    registered ones otherwise)."""
    feature = INPUT_FEATURES.load(name)
    if not isinstance(feature, InputFeature):
        kind = type(feature).__name__
        raise TypeError(f"input feature {name!r} is a {kind}, not an InputFeature")
    return feature


def input_width(inputs: tuple[str, ...]) -> int:
    """F, the per-neuron LSTM input width: the paper's 2 plus each feature's width."""
    return 2 + sum(input_feature(name).width for name in inputs)


def per_neuron_inputs(
    obs: Mapping[str, torch.Tensor],
    inputs: tuple[str, ...],
    *,
    v_rest_mV: float,
    v_threshold_mV: float,
    dtype: torch.dtype,
) -> torch.Tensor:
    """Per-neuron LSTM input [..., n, F]: each neuron's normalised voltage, whether it was
    stimulated at t-1, then the columns of each feature ``inputs`` names, in order."""
    voltage = normalised_voltage(obs["voltage"].to(dtype), v_rest_mV, v_threshold_mV)  # [..., n]
    n = voltage.shape[-1]
    columns = [voltage[..., None], neuron_indicator(obs["last_action"], n, dtype)[..., None]]
    for name in inputs:
        columns.append(input_feature(name).compute(obs, voltage, dtype))  # [..., n, width]
    return torch.cat(columns, dim=-1)  # [..., n, F]


def _target(obs: Mapping[str, torch.Tensor], voltage: torch.Tensor, dtype: torch.dtype):
    return neuron_indicator(obs["target"], voltage.shape[-1], dtype)[..., None]  # [..., n, 1]


def _target_voltage(obs: Mapping[str, torch.Tensor], voltage: torch.Tensor, dtype: torch.dtype):
    target_voltage = torch.gather(voltage, -1, obs["target"].unsqueeze(-1))  # [..., 1]
    return target_voltage.expand_as(voltage)[..., None]  # [..., n, 1]


def _others_spiking(obs: Mapping[str, torch.Tensor], voltage: torch.Tensor, dtype: torch.dtype):
    spiking = (voltage >= VISIBLE_SPIKE_LEVEL).to(dtype)  # [..., n]
    return (spiking.sum(-1, keepdim=True) - spiking)[..., None]  # [..., n, 1]


def _actions_in_flight(obs: Mapping[str, torch.Tensor], voltage: torch.Tensor, dtype: torch.dtype):
    """Column j: 1 on the neuron the action landing j steps from now stimulates (slot j of
    ``actions_in_flight``, oldest first); slots the loop does not have stay 0, so one
    network reads every latency up to MAX_LATENCY_STEPS (and none)."""
    n = voltage.shape[-1]
    columns = voltage.new_zeros(*voltage.shape, MAX_LATENCY_STEPS, dtype=dtype)  # [..., n, 5]
    in_flight = obs.get(IN_FLIGHT_KEY)
    if in_flight is None:
        return columns
    latency = in_flight.shape[-1]
    neurons = torch.arange(n, device=voltage.device)
    lands_on = in_flight.long()[..., None, :] == neurons[:, None]  # [..., n, L]
    columns[..., :latency] = lands_on.to(dtype)
    return columns


def _proximity(obs: Mapping[str, torch.Tensor], voltage: torch.Tensor, dtype: torch.dtype):
    positions = neuron_positions(obs, voltage.shape[-1], dtype)  # [..., n]
    return target_proximity(positions, obs["target"])[..., None]  # [..., n, 1]


INPUT_FEATURES.register("target", InputFeature(
    1, _target, "1 on the target neuron (the paper has it only after the memory)",
    drqn_ignores=True,
))  # fmt: skip
INPUT_FEATURES.register("target-voltage", InputFeature(
    1, _target_voltage, "the target's normalised voltage, the same for every neuron",
    drqn_ignores=True,
))  # fmt: skip
INPUT_FEATURES.register("others-spiking", InputFeature(
    1, _others_spiking, "how many other neurons show a spike", drqn_ignores=True,
))  # fmt: skip
INPUT_FEATURES.register("proximity", InputFeature(
    1, _proximity, "the generator's prior of a synapse onto the target at their distance "
    "on the line (features.target_proximity; positions from obs['position'], else indices)",
))  # fmt: skip
INPUT_FEATURES.register("actions-in-flight", InputFeature(
    MAX_LATENCY_STEPS, _actions_in_flight, "the actions in flight under loop latency: "
    "column j is 1 on the neuron stimulated j steps from now (0 without latency)",
))  # fmt: skip
