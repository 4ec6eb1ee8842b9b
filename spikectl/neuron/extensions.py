"""Extensions of the paper's environment (docs/extensions.md; paper Section 5.1 and the Discussion).

The paper's environment leaves out "non-observable neurons, neurons with different
dynamics, background noise, photobleaching effects, and stochastic activity
propagation" and excludes the target from the actions. :class:`Extensions` switches
each of them on; every field's default is off, and with all defaults the environment
is exactly the paper's, bit for bit.

Two kinds of field:

- **context level** (hidden neurons, heterogeneous neurons): drawn once per context by
  :meth:`spikectl.ContextSet.generate` / :func:`spikectl.make_splits` and saved with
  the set (:class:`Heterogeneity` and ``Context.hidden``);
- **environment level** (measurement noise, photobleaching, stochastic release,
  background activity, the target as an action, loop latency): applied by the
  environments, drawn from their own seeded generators, and saved in their Gymnasium spec.

This module holds the settings, the per-context data and the pure functions that draw
and apply them; ``docs/extensions.md`` is the reference table.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from spikectl.config_errors import ConfigError, ConfigTypeError
from spikectl.neuron.heterogeneity import Heterogeneity, draw_hidden  # noqa: F401 (lived here)
from spikectl.neuron.opsin import check_actuator
from spikectl.neuron.params import NeuronParams

CONTEXT_FIELDS = (
    "hidden_neurons",
    "hidden_fraction",
    "threshold_spread",
    "time_constant_spread",
    "synaptic_spread",
)
"""Fields drawn with the contexts and saved in the context set."""


MAX_BACKGROUND_RATE = 1000.0
"""Spontaneous inputs per neuron per step, at most (the registered variant uses 0.005)."""
MAX_BACKGROUND_CURRENT_pA = 1e6
"""The largest spontaneous input current in pA, either sign (the default is 600)."""
MAX_LATENCY_STEPS = 5
"""The longest loop latency in steps (a rig's round trip is 1-3 ms)."""
SENSING_MODES = ("potentials", "spikes")
"""What the agent observes of the neurons: the paper's potentials, or spikes only."""


@dataclass(frozen=True)
class Extensions:
    """Frozen, validated switches for the extensions; the defaults are the paper's model."""

    hidden_neurons: int = 0
    """Context level: neurons per network that are simulated but neither observed nor
    stimulable (never the target). Exclusive with ``hidden_fraction``."""
    hidden_fraction: float = 0.0
    """Context level: the same as a fraction of n, rounded to the nearest count (halves up)."""
    threshold_spread: float = 0.0
    """Context level: each neuron's threshold distance V_th - V_r is the default times a
    factor drawn uniformly from [1 - s, 1 + s]."""
    time_constant_spread: float = 0.0
    """Context level: each neuron's membrane time constant R C, likewise."""
    synaptic_spread: float = 0.0
    """Context level: each synapse's strength w_in, likewise (sign kept)."""
    observation_noise_mV: float = 0.0
    """Environment level: sigma of Gaussian measurement noise on observed potentials."""
    bleaching_time_constant_steps: float | None = None
    """Environment level: the observed amplitude V - V_r decays as exp(-step / tau);
    None is no photobleaching."""
    stochastic_release: bool = False
    """Environment level: a spike releases with probability p_r (1 - exp(-(t - t_r) /
    tau_R)) instead of when that expression is >= 0.5 (one draw per neuron)."""
    background_rate: float = 0.0
    """Environment level: expected spontaneous inputs per neuron per step (Poisson)."""
    background_current_pA: float = 600.0
    """Environment level: current of one spontaneous input for one step (600 pA: +20 mV,
    like one excitatory synapse; negative is inhibitory)."""
    allow_target_action: bool = False
    """Environment level: stimulating the target neuron is a legal action."""
    latency_steps: int = 0
    """Environment level: loop latency L, an action chosen at step t stimulates at t + L."""
    actuator: str = "pulse"
    """Environment level: ``"pulse"``, the paper's current pulse for one step, or
    ``"chr2"``, a 1 ms light pulse on a ChR2-expressing neuron (spikectl.neuron.opsin)."""
    light_irradiance_mW_per_mm2: float = 5.0
    """Environment level, with ``actuator="chr2"``: the fibre tip's irradiance in a pulse
    (5 mW/mm^2: one pulse makes a resting neuron spike at the next step)."""
    sensing: str = "potentials"
    """Environment level: ``"potentials"``, the paper's membrane potentials, or
    ``"spikes"``, spikes-only sensing: the observation's ``spikes`` (which neurons spiked
    at the last step) replaces its ``voltage``."""
    recorded_neurons: int | None = None
    """Environment level, with ``sensing="spikes"``: the number of observed neurons whose
    spikes are recorded, drawn per episode, the target always among them (the others
    report none; the observation's ``recorded`` marks which); None records every one."""

    CONTEXT_FIELDS: ClassVar[tuple[str, ...]] = CONTEXT_FIELDS

    def __post_init__(self) -> None:
        for name in ("stochastic_release", "allow_target_action"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ConfigTypeError(name, f"must be a bool, got {getattr(self, name)!r}",
                                      label=f"Extensions.{name}")  # fmt: skip
            object.__setattr__(self, name, bool(getattr(self, name)))
        for name, high in (("hidden_neurons", None), ("latency_steps", MAX_LATENCY_STEPS)):
            count = getattr(self, name)
            if isinstance(count, (bool, np.bool_)) or not isinstance(count, (int, np.integer)):
                raise ConfigTypeError(name, f"must be an integer, got {count!r}",
                                      label=f"Extensions.{name}")  # fmt: skip
            if count < 0 or (high is not None and count > high):
                bounds = "be >= 0" if high is None else f"lie in 0..{high}"
                raise ConfigError(name, f"must {bounds}, got {count}",
                                  label=f"Extensions.{name}")  # fmt: skip
            object.__setattr__(self, name, int(count))
        for field in fields(self):
            value = getattr(self, field.name)
            if field.name in ("actuator", "sensing", "recorded_neurons"):  # checked below
                continue
            if field.name in ("stochastic_release", "allow_target_action", "hidden_neurons",
                              "latency_steps"):  # fmt: skip
                continue
            if value is None and field.name == "bleaching_time_constant_steps":
                continue
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float)):
                raise ConfigTypeError(field.name, f"must be a number, got {value!r}",
                                      label=f"Extensions.{field.name}")  # fmt: skip
            if not math.isfinite(value):
                raise ConfigError(field.name, f"must be finite, got {value!r}",
                                  label=f"Extensions.{field.name}")  # fmt: skip
            object.__setattr__(self, field.name, float(value))
        for name in ("hidden_fraction", "threshold_spread", "time_constant_spread",
                     "synaptic_spread"):  # fmt: skip
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ConfigError(name, f"must lie in [0, 1), got {getattr(self, name)}",
                                  label=f"Extensions.{name}")  # fmt: skip
        if self.hidden_neurons and self.hidden_fraction:
            raise ConfigError("hidden_fraction", "give hidden_neurons or hidden_fraction, not both",
                              label="")  # fmt: skip
        for name in ("observation_noise_mV", "background_rate"):
            if getattr(self, name) < 0:
                raise ConfigError(name, f"must be >= 0, got {getattr(self, name)}",
                                  label=f"Extensions.{name}")  # fmt: skip
        # Beyond these no network is anything but noise, and NumPy's Poisson draws and
        # the voltage sums overflow (a rate of 1e30 was "lam value too large").
        if self.background_rate > MAX_BACKGROUND_RATE:
            raise ConfigError(
                "background_rate",
                f"must be at most {MAX_BACKGROUND_RATE:g} inputs per neuron per step, got "
                f"{self.background_rate:g}", label="Extensions.background_rate",
            )  # fmt: skip
        if not abs(self.background_current_pA) <= MAX_BACKGROUND_CURRENT_pA:
            raise ConfigError(
                "background_current_pA",
                f"must lie in [-{MAX_BACKGROUND_CURRENT_pA:g}, {MAX_BACKGROUND_CURRENT_pA:g}] "
                f"pA, got {self.background_current_pA:g}",
                label="Extensions.background_current_pA",
            )  # fmt: skip
        check_actuator(self.actuator, self.light_irradiance_mW_per_mm2)
        self._check_sensing()
        bleaching = self.bleaching_time_constant_steps
        if bleaching is not None and bleaching <= 0:
            raise ConfigError(
                "bleaching_time_constant_steps", f"must be > 0 or None, got {bleaching}",
                label="Extensions.bleaching_time_constant_steps",
            )  # fmt: skip

    def _check_sensing(self) -> None:
        if not isinstance(self.sensing, str) or self.sensing not in SENSING_MODES:
            raise ConfigError("sensing", f"must be one of {', '.join(map(repr, SENSING_MODES))}"
                              f", got {self.sensing!r}", label="Extensions.sensing")  # fmt: skip
        # Noise and bleaching change observed potentials; spikes-only observes none, so
        # either would silently do nothing.
        if self.spikes_only and self.transforms_observation:
            raise ConfigError(
                "sensing", "'spikes' observes no potentials, so observation_noise_mV and "
                "bleaching_time_constant_steps (which act on them) must be off",
                label="Extensions.sensing",
            )  # fmt: skip
        recorded = self.recorded_neurons
        if recorded is None:
            return
        label = "Extensions.recorded_neurons"
        if isinstance(recorded, (bool, np.bool_)) or not isinstance(recorded, (int, np.integer)):
            raise ConfigTypeError("recorded_neurons", f"must be an integer or None, got "
                                  f"{recorded!r}", label=label)  # fmt: skip
        if recorded < 1:
            raise ConfigError("recorded_neurons", f"must be >= 1 (the target is always "
                              f"recorded) or None, got {recorded}", label=label)  # fmt: skip
        if not self.spikes_only:
            raise ConfigError("recorded_neurons", "records spikes: it needs sensing='spikes', "
                              f"got sensing={self.sensing!r}", label=label)  # fmt: skip
        object.__setattr__(self, "recorded_neurons", int(recorded))

    # -- which parts are on

    @property
    def spikes_only(self) -> bool:
        """True when the agent observes spikes, not potentials (``sensing="spikes"``)."""
        return self.sensing == "spikes"

    @property
    def lit(self) -> bool:
        """True when an action is a light pulse on an opsin, not the paper's current pulse
        (``actuator="chr2"``)."""
        return self.actuator != "pulse"

    @property
    def heterogeneous(self) -> bool:
        """True when neurons differ (any spread > 0)."""
        return bool(self.threshold_spread or self.time_constant_spread or self.synaptic_spread)

    @property
    def random_dynamics(self) -> bool:
        """True when the dynamics draw random numbers (stochastic release, background)."""
        return self.stochastic_release or self.background_rate > 0

    @property
    def transforms_observation(self) -> bool:
        """True when what is observed differs from the potentials (noise, bleaching)."""
        return self.observation_noise_mV > 0 or self.bleaching_time_constant_steps is not None

    def hidden_count(self, n_neurons: int) -> int:
        """Number of hidden neurons in a network of ``n_neurons``."""
        count = self.hidden_neurons or math.floor(self.hidden_fraction * n_neurons + 0.5)
        if count > n_neurons - 2:
            raise ValueError(
                f"{count} hidden neurons of {n_neurons} leave fewer than 2 observable ones "
                "(the target and one neuron to stimulate)"
            )
        return count

    def recorded_count(self, n_observed: int) -> int | None:
        """How many of ``n_observed`` neurons are recorded per episode; None: every one,
        the option off. More than ``n_observed`` is a ConfigError naming the field."""
        count = self.recorded_neurons
        if count is not None and count > n_observed:
            raise ConfigError(
                "recorded_neurons", f"must be at most the {n_observed} observed neurons, "
                f"got {count}", label="Extensions.recorded_neurons",
            )  # fmt: skip
        return count

    def context_part(self) -> Extensions:
        """Only the context-level fields (the rest at their defaults)."""
        return Extensions(**{name: getattr(self, name) for name in CONTEXT_FIELDS})

    def environment_part(self) -> Extensions:
        """Only the environment-level fields (the rest at their defaults)."""
        default = Extensions()
        return replace(self, **{name: getattr(default, name) for name in CONTEXT_FIELDS})

    def to_dict(self, *, only_changed: bool = False) -> dict[str, Any]:
        """Plain (JSON-ready) dict of the fields; ``only_changed`` drops defaults."""
        values = asdict(self)
        if only_changed:
            default = asdict(Extensions())
            values = {key: value for key, value in values.items() if value != default[key]}
        return values

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Extensions:
        """Inverse of :meth:`to_dict`; unknown keys are an error, not silently dropped."""
        known = {field.name for field in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"unknown Extensions field(s): {', '.join(unknown)}; "
                f"known: {', '.join(sorted(known))}"
            )
        return cls(**values)

    @classmethod
    def coerce(cls, value: Extensions | Mapping[str, Any] | None) -> Extensions:
        """An ``Extensions`` from itself, a dict of fields (e.g. from a JSON spec) or None."""
        if value is None:
            return cls()
        if isinstance(value, Extensions):
            return value
        if isinstance(value, Mapping):
            return cls.from_dict(value)
        raise TypeError(f"extensions must be an Extensions, a dict or None, got {value!r}")


def draw_heterogeneity(
    rng: np.random.Generator,
    weights: np.ndarray,
    params: NeuronParams,
    extensions: Extensions,
) -> Heterogeneity | None:
    """Per-neuron thresholds and time constants and per-synapse strengths; None if off.

    Each is the default times 1 + s (2u - 1), u uniform in [0, 1): uniform on
    [1 - s, 1 + s] around the default. The threshold factor applies to the distance
    V_th - V_r. All three are drawn whenever any spread is on (a spread of 0 gives
    exactly the default), so their draws do not depend on which are on.
    """
    if not extensions.heterogeneous:
        return None
    n = weights.shape[0]

    def factors(spread: float, shape: tuple[int, ...]) -> np.ndarray:
        return 1.0 + spread * (2.0 * rng.random(shape) - 1.0)

    distance = params.v_threshold_mV - params.v_rest_mV
    thresholds = params.v_rest_mV + distance * factors(extensions.threshold_spread, (n,))
    time_constants = params.membrane_time_constant_ms * factors(
        extensions.time_constant_spread, (n,)
    )
    if time_constants.min() < params.dt_ms:
        raise ValueError(
            f"time_constant_spread {extensions.time_constant_spread} gives a membrane time "
            f"constant below dt ({params.dt_ms} ms): the Euler step would overshoot rest"
        )
    scale = factors(extensions.synaptic_spread, (n, n))
    scale[np.asarray(weights) == 0] = 1.0
    return Heterogeneity(thresholds, time_constants, scale)


class EnvironmentEffects:
    """The environment-level extensions at run time: what an environment draws and observes.

    Every random number comes from the generator passed in (the environment's
    ``np_random``), in a fixed order per step: release uniforms [n], then background
    input counts [n], then (after the step is simulated) measurement noise [k].
    """

    def __init__(self, extensions: Extensions, params: NeuronParams, episode_length: int):
        self.extensions = extensions
        self.v_rest_mV = params.v_rest_mV
        self.noise_mV = extensions.observation_noise_mV
        self.stochastic_release = extensions.stochastic_release
        self.background_rate = extensions.background_rate
        self.background_step_mV = params.voltage_step_mV(extensions.background_current_pA)
        tau = extensions.bleaching_time_constant_steps
        # The C library's scalar exp, not np.exp: NumPy's SIMD kernels (AVX-512, AVX2, the
        # baseline) differ in the last bit, and the observations would with them.
        self.bleaching = (
            None if tau is None
            else np.array([math.exp(-step / tau) for step in range(episode_length + 1)])
        )  # fmt: skip
        self.plain = not extensions.transforms_observation
        self.random_dynamics = extensions.random_dynamics
        self.opsin = extensions.lit

    def draw_inputs(
        self,
        rng: np.random.Generator,
        release_uniforms: np.ndarray | None,
        input_mV: np.ndarray | None,
    ) -> None:
        """Fill one network's release uniforms [n] and background input [n] for one step.

        Each is None when its extension is off (and then nothing is drawn for it).
        """
        if release_uniforms is not None:
            release_uniforms[:] = rng.random(release_uniforms.shape[-1])
        if input_mV is not None and self.background_rate > 0:
            counts = rng.poisson(self.background_rate, input_mV.shape[-1])
            input_mV[:] = counts * self.background_step_mV

    def input_buffers(self, batch: int, n_neurons: int) -> tuple[np.ndarray | None, ...]:
        """Zeroed kernel inputs [batch, 1, n] for one step: (release uniforms, input_mV);
        None for an extension that is off."""
        release = np.zeros((batch, 1, n_neurons)) if self.stochastic_release else None
        background = (
            np.zeros((batch, 1, n_neurons)) if self.background_rate > 0 or self.opsin else None
        )  # the opsin's current enters as input too
        return release, background

    def observe(self, voltage: np.ndarray, steps: np.ndarray | int, noise: np.ndarray | None):
        """Observed potentials (float32) from true ones [..., k] at observation ``steps``.

        Photobleaching scales V - V_r by exp(-step / tau) (``steps`` is the
        observation's ``step`` index: 0 after reset, t + 1 after step t); then
        ``noise`` (standard normal, same shape) times sigma is added.
        """
        observed = np.asarray(voltage, dtype=np.float64)
        if self.bleaching is not None:
            factor = self.bleaching[steps]
            if np.ndim(factor):
                factor = factor[:, None]
            observed = self.v_rest_mV + (observed - self.v_rest_mV) * factor
        if noise is not None:
            observed = observed + self.noise_mV * noise
        return observed.astype(np.float32)

    def draw_noise(self, rng: np.random.Generator, k: int) -> np.ndarray | None:
        """Standard normal noise [k] for one observation, or None without noise."""
        return rng.standard_normal(k) if self.noise_mV > 0 else None
