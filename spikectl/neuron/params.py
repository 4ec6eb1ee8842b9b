"""Parameters of the leaky integrate-and-fire model with short-term depression.

The defaults are the paper's Table 1 as docs/model.md reads it. Units are in the
field names: mV, ms, pA, pF and GOhm, chosen so that pA / pF = mV / ms and
GOhm * pF = ms; in these units every default is exactly representable and the
potential of a neuron at rest that receives one excitatory input is exactly
-50 mV (the threshold), with no round-off to decide whether it fires.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from functools import cached_property
from typing import Any

import numpy as np

from spikectl.config_errors import ConfigError, ConfigTypeError

NEVER_RELEASES = 2**31 - 1
"""``min_release_interval_steps`` when the release rule can never be met (p_r < 0.5)."""
MAX_REFRACTORY_STEPS = 2**30
"""The simulator counts refractory steps in int32; longer periods would wrap."""

MAX_VOLTAGE_STEP_mV = 10_000.0
"""The largest voltage step one stimulation or release may cause (the paper's are 40 and
20 mV): beyond it, sums of steps overflow into NaN long before any spike means anything."""


@dataclass(frozen=True)
class NeuronParams:
    """Frozen, validated parameters of the neuron and synapse model (docs/model.md)."""

    v_rest_mV: float = -70.0
    """Resting and reset potential V_r."""
    v_threshold_mV: float = -50.0
    """Spike threshold V_th (inclusive, within ``threshold_tolerance_mV``)."""
    threshold_tolerance_mV: float = 1e-6
    """A neuron spikes when V >= V_th - tolerance, so round-off never decides a spike."""
    resistance_GOhm: float = 2.0 / 3.0
    """Membrane resistance R."""
    capacitance_pF: float = 30.0
    """Membrane capacitance C (R * C = 20 ms by default)."""
    stimulus_current_pA: float = 1200.0
    """External input w_e for the one step a neuron is stimulated (+40 mV)."""
    synaptic_current_pA: float = 600.0
    """Synaptic input w_in per released presynaptic neuron, signed by G (+/-20 mV)."""
    release_scale: float = 0.65
    """p_r: a spike releases vesicles iff p_r * (1 - exp(-dt_since_release / tau_R)) >= 0.5."""
    vesicle_recovery_ms: float = 3.0
    """tau_R, the time constant of vesicle recovery."""
    refractory_steps: int = 1
    """Steps after a spike during which the neuron is held at V_r and ignores input."""
    dt_ms: float = 1.0
    """Euler time step; one environment step."""

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise ConfigTypeError(field.name, f"must be a number, got {value!r}",
                                      label=f"NeuronParams.{field.name}")  # fmt: skip
            if not math.isfinite(value):
                raise ConfigError(field.name, f"must be finite, got {value!r}",
                                  label=f"NeuronParams.{field.name}")  # fmt: skip
            # NumPy scalars become Python numbers, so to_dict() stays JSON-ready.
            value = int(value) if isinstance(value, (int, np.integer)) else float(value)
            object.__setattr__(self, field.name, value)
        if self.v_threshold_mV <= self.v_rest_mV:
            raise ConfigError(
                "v_threshold_mV",
                f"({self.v_threshold_mV}) must be above v_rest_mV ({self.v_rest_mV})",
            )
        positive = ("resistance_GOhm", "capacitance_pF", "vesicle_recovery_ms", "dt_ms")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(name, f"must be > 0, got {getattr(self, name)}",
                                  label=f"NeuronParams.{name}")  # fmt: skip
        nonnegative = ("threshold_tolerance_mV", "stimulus_current_pA", "synaptic_current_pA")
        for name in nonnegative:
            if getattr(self, name) < 0:
                raise ConfigError(name, f"must be >= 0, got {getattr(self, name)}",
                                  label=f"NeuronParams.{name}")  # fmt: skip
        if not 0.0 <= self.release_scale <= 1.0:
            raise ConfigError("release_scale", f"must lie in [0, 1], got {self.release_scale}")
        if (
            int(self.refractory_steps) != self.refractory_steps
            or not 0 <= self.refractory_steps <= MAX_REFRACTORY_STEPS
        ):
            raise ConfigError(
                "refractory_steps",
                f"must be an integer in 0..{MAX_REFRACTORY_STEPS}, got {self.refractory_steps}",
            )
        object.__setattr__(self, "refractory_steps", int(self.refractory_steps))
        if self.v_rest_mV >= self.v_threshold_mV - self.threshold_tolerance_mV:
            raise ConfigError(
                "threshold_tolerance_mV",
                f"({self.threshold_tolerance_mV}) must be smaller than "
                f"v_threshold_mV - v_rest_mV ({self.v_threshold_mV - self.v_rest_mV}): "
                "otherwise resting neurons spike at every step",
            )
        for current in ("stimulus_current_pA", "synaptic_current_pA"):
            step = self.voltage_step_mV(getattr(self, current))
            if not step <= MAX_VOLTAGE_STEP_mV:
                raise ConfigError(
                    current,
                    f"({getattr(self, current):g}) moves a neuron by {step:g} mV in one step "
                    f"(dt I / C); more than {MAX_VOLTAGE_STEP_mV:g} mV is no neuron's",
                    label=f"NeuronParams.{current}",
                )
        if self.dt_ms / (self.resistance_GOhm * self.capacitance_pF) > 1.0:
            raise ConfigError(
                "dt_ms",
                "exceeds the membrane time constant R*C: the Euler step would overshoot rest",
            )

    @property
    def membrane_time_constant_ms(self) -> float:
        """tau_m = R * C, in ms."""
        return self.resistance_GOhm * self.capacitance_pF

    @property
    def leak_per_step(self) -> float:
        """dt / (R C), dimensionless: the fraction of V - V_r that one step leaks away."""
        return self.dt_ms / self.membrane_time_constant_ms

    def voltage_step_mV(self, current_pA: float) -> float:
        """dt * I / C, in mV: what a current of ``current_pA`` held for one step adds to V."""
        return self.dt_ms * current_pA / self.capacitance_pF

    @property
    def stimulus_step_mV(self) -> float:
        """dt * w_e / C, in mV: the voltage step of one stimulation (+40 mV by default)."""
        return self.voltage_step_mV(self.stimulus_current_pA)

    @property
    def synaptic_step_mV(self) -> float:
        """dt * w_in / C, in mV: the voltage step of one release onto a synapse of weight 1
        (+20 mV by default; G[i, j] signs it)."""
        return self.voltage_step_mV(self.synaptic_current_pA)

    @property
    def v_spike_mV(self) -> float:
        """V_th - tolerance, in mV: a neuron spikes iff its potential is at least this."""
        return self.v_threshold_mV - self.threshold_tolerance_mV

    @property
    def recovery_per_step(self) -> float:
        """dt / tau_R, dimensionless: k steps after a release, p_r * (1 - exp(-k * this))
        is the chance (stochastic release) or the rule's left side (the paper's)."""
        return self.dt_ms / self.vesicle_recovery_ms

    @cached_property
    def min_release_interval_steps(self) -> int:
        """Smallest number of steps k >= 1 since the last release for which a spike releases.

        The release rule p_r * (1 - exp(-k dt / tau_R)) >= 0.5 is monotone in k, so it
        reduces to k >= this interval (5 with the defaults). ``NEVER_RELEASES`` when
        the rule cannot be met (p_r < 0.5).
        """
        if self.release_scale < 0.5:
            return NEVER_RELEASES
        for k in range(1, 100_000):
            if (
                self.release_scale * (1.0 - math.exp(-k * self.dt_ms / self.vesicle_recovery_ms))
                >= 0.5
            ):
                return k
        return NEVER_RELEASES

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the fields, for saving next to results."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> NeuronParams:
        """Inverse of :meth:`to_dict`; unknown keys are an error, not silently dropped."""
        known = {field.name for field in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown NeuronParams field(s): {', '.join(unknown)}")
        return cls(**values)
