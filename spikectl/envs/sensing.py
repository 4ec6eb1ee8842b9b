"""Spikes-only sensing (docs/extensions.md, ``Extensions(sensing="spikes")``).

A rig's electrodes or imaging report spikes, not every neuron's sub-threshold potential.
With spikes-only sensing the observation has ``spikes`` (int8 [k]: 1 for each observable
neuron that spiked at the step just simulated, all 0 after reset) in place of
``voltage``; every other key is the paper's. A spike is what the paper's observation
shows as a potential at or above the threshold, so spikes-only sees a function of what
the paper's agent sees. With the default, ``"potentials"``, nothing here changes the
environments.

With ``recorded_neurons`` m (a recording of a subset, ``Extensions(sensing="spikes",
recorded_neurons=m)``) only m of the k observable neurons are recorded in an episode: the
target and m - 1 others drawn at reset from the environment's own generator
(:class:`Recording`). The others report no spike, and the observation's ``recorded``
(int8 [k], 1 = recorded) says which are which. Without it there is no such key and
nothing is drawn.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from spikectl.envs.latency import IN_FLIGHT_KEY

SPIKES_KEY = "spikes"
"""The observation key of the spikes (present only with spikes-only sensing)."""
VOLTAGE_KEY = "voltage"
"""The observation key of the potentials (absent with spikes-only sensing)."""
RECORDED_KEY = "recorded"
"""The observation key of the recorded neurons (present only with ``recorded_neurons``)."""


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
    recorded: np.ndarray | None = None,
) -> dict[str, Any]:
    """One observation (or a batch): what is sensed under its key, then the paper's
    other keys in the paper's order, then the actions in flight (with latency only), then
    the recorded neurons (with ``recorded_neurons`` only)."""
    observation = {
        sensed_key(spikes_only): sensed,
        "target": target,
        "pattern": pattern,
        "step": step,
        "last_action": last_action,
    }
    if in_flight is not None:
        observation[IN_FLIGHT_KEY] = in_flight
    if recorded is not None:
        observation[RECORDED_KEY] = recorded
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


class Sensing(NamedTuple):
    """What an environment's observation shows of its neurons (the flat codec's switch)."""

    spikes_only: bool = False
    """Spikes in place of potentials (``sensing="spikes"``)."""
    recorded: bool = False
    """A recorded subset, marked by the observation's ``recorded`` (``recorded_neurons``)."""

    @classmethod
    def of(cls, extensions: Any) -> Sensing:
        """The sensing of an environment's (effective) ``Extensions``."""
        return cls(extensions.spikes_only, extensions.recorded_neurons is not None)


class Recording:
    """The recorded neurons of a batch of B environments (``recorded_neurons`` = m).

    ``mask`` int8 [B, k] (1 = recorded) is what the observations' ``recorded`` shows.
    At each reset an environment records its target and m - 1 of its other k - 1 observed
    neurons, uniformly: it draws ``rng.random(k)`` from its own generator (after its
    context), and the others with the m - 1 smallest numbers are recorded. With m = k
    every neuron is recorded and nothing is drawn.
    """

    def __init__(self, batch: int, n_observed: int, count: int) -> None:
        self.count = int(count)
        self.mask = np.ones((batch, n_observed), dtype=np.int8)

    @classmethod
    def of(cls, extensions: Any, batch: int, n_observed: int) -> Recording | None:
        """The recording of ``extensions`` for B environments of k observed neurons, or
        None without ``recorded_neurons`` (a ConfigError when it exceeds k)."""
        count = extensions.recorded_count(n_observed)
        return None if count is None else cls(batch, n_observed, count)

    def draw(
        self, rngs: Sequence[np.random.Generator], envs: np.ndarray, targets: np.ndarray
    ) -> None:
        """New recorded neurons for ``envs`` (their episodes start), each from its own
        generator in ``rngs`` (one per env), the targets (agent indices) among them."""
        k = self.mask.shape[1]
        if self.count == k or len(envs) == 0:
            return
        uniforms = np.stack([rng.random(k) for rng in rngs])  # [m, k]
        rows = np.arange(len(envs))
        uniforms[rows, targets] = -1.0  # below every draw: the target comes first
        chosen = np.argsort(uniforms, axis=1, kind="stable")[:, : self.count]
        mask = np.zeros_like(uniforms, dtype=np.int8)
        mask[rows[:, None], chosen] = 1
        self.mask[envs] = mask

    def sense(self, spikes: np.ndarray, which: slice | int = slice(None)) -> np.ndarray:
        """int8 spikes [..., k] as recorded: each unrecorded neuron's as 0 (``which``:
        the environments ``spikes`` belongs to)."""
        return np.multiply(spikes, self.mask[which], dtype=np.int8)
