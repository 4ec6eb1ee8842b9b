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

from collections.abc import Mapping
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


def with_sensed_potentials(
    observations: Mapping[str, Any], v_rest_mV: float, v_threshold_mV: float
) -> Mapping[str, Any]:
    """The observation (one, or a batch) as a potential-reading agent reads it.

    Under spikes-only sensing a spike is what the paper's observation shows as a potential
    at threshold: the result adds ``voltage`` (float32, the shape of ``spikes``), V_th
    where a neuron spiked and V_r elsewhere, so that the agents' normalised potential
    (V - V_r) / (V_th - V_r) is the spike itself (0 or 1, exactly), as the flat ids'
    voltage columns hold it. An observation with ``voltage`` (the paper's sensing) comes
    back unchanged, the very object. The agents read it; controllers that identify
    from spikes read :func:`as_sensed` of it.
    """
    if VOLTAGE_KEY in observations or SPIKES_KEY not in observations:
        return observations
    spiked = np.asarray(observations[SPIKES_KEY]) != 0
    voltage = np.where(spiked, np.float32(v_threshold_mV), np.float32(v_rest_mV))
    return {VOLTAGE_KEY: voltage.astype(np.float32, copy=False), **observations}


def as_sensed(observations: Mapping[str, Any]) -> Mapping[str, Any]:
    """The observation as the environment gave it: without the ``voltage`` that
    :func:`with_sensed_potentials` added beside ``spikes`` (unchanged otherwise)."""
    if SPIKES_KEY in observations and VOLTAGE_KEY in observations:
        return {key: value for key, value in observations.items() if key != VOLTAGE_KEY}
    return observations
