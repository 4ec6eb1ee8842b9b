"""Spikes-only sensing (docs/extensions.md, ``Extensions(sensing="spikes")``).

A rig's electrodes or imaging report spikes, not every neuron's sub-threshold potential.
With spikes-only sensing the observation has ``spikes`` (int8 [k]: 1 for each observable
neuron that spiked at the step just simulated, all 0 after reset) in place of
``voltage``; every other key is the paper's. A spike is what the paper's observation
shows as a potential at or above the threshold, so spikes-only sees a function of what
the paper's agent sees. With the default, ``"potentials"``, nothing here changes the
environments.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from spikectl.envs.latency import IN_FLIGHT_KEY

SPIKES_KEY = "spikes"
"""The observation key of the spikes (present only with spikes-only sensing)."""
VOLTAGE_KEY = "voltage"
"""The observation key of the potentials (absent with spikes-only sensing)."""


def sensed_key(spikes_only: bool) -> str:
    """The observation's key for what is sensed of the neurons."""
    return SPIKES_KEY if spikes_only else VOLTAGE_KEY


def sensed_space(n_neurons: int, spikes_only: bool) -> spaces.Space:
    """The space of what is sensed: potentials in mV, or which neurons spiked (int8)."""
    if spikes_only:
        return spaces.MultiBinary(n_neurons)
    return spaces.Box(-np.inf, np.inf, (n_neurons,), np.float32)


def make_observation(
    sensed: np.ndarray,
    spikes_only: bool,
    target: Any,
    pattern: np.ndarray,
    step: Any,
    last_action: Any,
    in_flight: np.ndarray | None = None,
) -> dict[str, Any]:
    """One observation (or a batch): what is sensed under its key, then the paper's
    other keys in the paper's order, then the actions in flight (with latency only)."""
    observation = {
        sensed_key(spikes_only): sensed,
        "target": target,
        "pattern": pattern,
        "step": step,
        "last_action": last_action,
    }
    if in_flight is not None:
        observation[IN_FLIGHT_KEY] = in_flight
    return observation
