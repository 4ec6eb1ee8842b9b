"""Featurisation: pure functions from observation tensors to the networks' inputs.

Shapes in comments use n = neurons, N = episode length (= pattern length) and
F = per-neuron input features; ``...`` is any leading shape (``[B]`` or ``[B, T]``).
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
import torch.nn.functional as F

from spikectl.contexts.generation import (
    CONNECTION_PROBABILITY_BANDS,
    LONG_RANGE_CONNECTION_PROBABILITY,
)


def normalised_voltage(
    voltage: torch.Tensor, v_rest_mV: float, v_threshold_mV: float
) -> torch.Tensor:
    """(V - V_r) / (V_th - V_r): 0 at rest, 1 at threshold (a visible spike is >= 1)."""
    return (voltage - v_rest_mV) / (v_threshold_mV - v_rest_mV)


def neuron_indicator(index: torch.Tensor, n: int, dtype: torch.dtype) -> torch.Tensor:
    """[...] integer → [..., n] with 1 where the neuron is ``index`` (-1 gives all zeros)."""
    neurons = torch.arange(n, device=index.device)  # [n]
    return (index.unsqueeze(-1) == neurons).to(dtype)  # [..., n]


def action_one_hot(last_action: torch.Tensor, n: int, dtype: torch.dtype) -> torch.Tensor:
    """[...] action in -1..n-1 → [..., n+1] one-hot in Q-vector order (index = action + 1)."""
    return F.one_hot(last_action + 1, n + 1).to(dtype)  # [..., n+1]


def shift_pattern(pattern: torch.Tensor, step: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Shift the pattern so step t comes first, pad with -1 to length N (paper App. C).

    pattern [..., N] (0/1), step [...] in 0..N → [..., N] equal to
    ``pattern[t:N]`` followed by ``t`` entries of -1 (all -1 at t = N).
    """
    N = pattern.shape[-1]
    index = step.unsqueeze(-1) + torch.arange(N, device=step.device)  # [..., N]
    shifted = torch.gather(pattern.to(dtype), -1, index.clamp(max=N - 1))  # [..., N]
    return torch.where(index < N, shifted, torch.full_like(shifted, -1.0))  # [..., N]


def neuron_positions(obs: Mapping[str, torch.Tensor], n: int, dtype: torch.dtype) -> torch.Tensor:
    """[..., n] each neuron's position on the generator's line: ``obs["position"]`` where
    the observation holds it, else the neuron's index (the environments' neurons lie on
    the line in index order; docs/model.md)."""
    position = obs.get("position")
    if position is not None:
        return position.to(dtype)  # [..., n]
    index = torch.arange(n, device=obs["voltage"].device, dtype=dtype)  # [n]
    return index.expand(obs["voltage"].shape)  # [..., n]


def target_proximity(position: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """[..., n] the generator's prior probability of a synapse from each neuron onto
    the target, by their distance on the line (``connection_probability`` of
    |p_i - p_target|: 0.3 within 4, 0.2 within 8, 0.1 within 12, 0.01 beyond), and 0
    at the target itself. Relative: it moves with the neurons under any relabelling
    that keeps each neuron's position."""
    target_position = torch.gather(position, -1, target.unsqueeze(-1))  # [..., 1]
    distance = (position - target_position).abs()  # [..., n]
    proximity = torch.full_like(distance, LONG_RANGE_CONNECTION_PROBABILITY)
    for max_distance, probability in reversed(CONNECTION_PROBABILITY_BANDS):
        proximity = torch.where(distance <= max_distance, probability, proximity)
    return torch.where(distance == 0, 0.0, proximity)  # [..., n]


def system_features(
    obs: Mapping[str, torch.Tensor], *, v_rest_mV: float, v_threshold_mV: float, dtype: torch.dtype
) -> torch.Tensor:
    """DRQN input [..., 2n+1]: all normalised potentials and the one-hot previous action."""
    voltage = obs["voltage"].to(dtype)  # [..., n]
    n = voltage.shape[-1]
    return torch.cat(
        [
            normalised_voltage(voltage, v_rest_mV, v_threshold_mV),  # [..., n]
            action_one_hot(obs["last_action"], n, dtype),  # [..., n+1]
        ],
        dim=-1,
    )  # [..., 2n+1]
