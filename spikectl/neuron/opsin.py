"""An optogenetic actuator: channelrhodopsin-2 (ChR2) under an optic fibre (docs/extensions.md).

With ``Extensions(actuator="chr2")`` an action is a 1 ms light pulse on one neuron
instead of the paper's current pulse. Every neuron expresses ChR2, modelled as Cleo
models it (``cleo.opto.chr2_4s()``: PyRhO's four-state model, Evans et al. 2016, with
its default fit): closed states C1, C2 and open states O1, O2, whose occupancies obey

    dC1/dt = Gd1 O1 + Gr0 C2 - Ga1 C1
    dO1/dt = Ga1 C1 + Gb O2 - (Gd1 + Gf) O1
    dO2/dt = Ga2 C2 + Gf O1 - (Gd2 + Gb) O2
    C2 = 1 - C1 - O1 - O2

with the light-dependent rates Ga1 = k1 H_p, Ga2 = k2 H_p, Gf = Gf0 + kf H_q,
Gb = Gb0 + kb H_q, H_x = phi^x / (phi^x + phi_m^x) for a photon flux phi > 0 (0 in
the dark). The neuron receives I = -g0 (O1 + gamma O2) v1 (1 - exp(-(V - E) / v0)) (positive:
depolarising).

The light comes from one 473 nm fibre 50 um above each neuron (Cleo's ``fiber473nm``,
the Foutz et al. 2012 model): at the neuron the irradiance is the tip's times the
transmittance T (Gaussian spread, geometric loss and Kubelka-Munk scattering), and
phi = epsilon T Irr / E_photon with ChR2's relative sensitivity epsilon = 1 at 473 nm.

Integration, as Cleo's Brian 2 model does it: the occupancies take forward Euler steps
of 0.1 ms (ChR2's 4.15/ms makes 1 ms steps unstable), the light of step t on during
the ten sub-steps of step t (applied as their composed affine map,
:func:`euler_step_map`); the membrane keeps its 1 ms Euler step, and the opsin
current it integrates over step t is the one computed once at the start of the step,
from the occupancies and the potential then (Brian updates the summed current on the
neurons' 1 ms clock, before their integration). So a pulse at step t drives the neuron
from step t + 1 on, and the channel keeps driving it for ~10 ms.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spikectl.config_errors import ConfigError

ACTUATORS = ("pulse", "chr2")
"""What an action may be (``Extensions.actuator``): the paper's current pulse, or a light
pulse on ChR2."""

# ChR2, Cleo 0.20's chr2_4s() (PyRhO's default four-state fit); rates in 1/ms.
G0_nS = 114.0
"""Maximal conductance g0 (114 000 pS)."""
GAMMA = 0.00742
"""Conductance of O2 relative to O1."""
PHI_M_PER_mm2_s = 2.33e17
"""Photon flux phi_m of half-maximal activation, photons / (mm^2 s)."""
K1_PER_ms = 4.15
"""Activation rate C1 -> O1 at saturating light, k1."""
K2_PER_ms = 0.868
"""Activation rate C2 -> O2 at saturating light, k2."""
P_EXPONENT = 0.833
"""Hill exponent p of the activation rates."""
GF0_PER_ms = 0.0373
"""Dark rate O1 -> O2, Gf0."""
KF_PER_ms = 0.0581
"""Light-dependent part of O1 -> O2, kf."""
GB0_PER_ms = 0.0161
"""Dark rate O2 -> O1, Gb0."""
KB_PER_ms = 0.063
"""Light-dependent part of O2 -> O1, kb."""
Q_EXPONENT = 1.94
"""Hill exponent q of the O1 <-> O2 rates."""
GD1_PER_ms = 0.105
"""Closing rate O1 -> C1, Gd1."""
GD2_PER_ms = 0.0138
"""Closing rate O2 -> C2, Gd2."""
GR0_PER_ms = 0.00033
"""Recovery rate C2 -> C1 (dark adaptation), Gr0."""
E_mV = 0.0
"""Reversal potential E."""
V0_mV = 43.0
"""Voltage scale v0 of the rectification."""
V1_mV = 17.1
"""Voltage factor v1 of the rectification."""

# The fibre: Cleo 0.20's fiber473nm() (Foutz et al. 2012).
FIBRE_RADIUS_mm = 0.1
"""Fibre core radius R0."""
FIBRE_NUMERICAL_APERTURE = 0.37
"""Numerical aperture of the fibre."""
ABSORBANCE_PER_mm = 0.125
"""Tissue absorbance coefficient K."""
SCATTERING_PER_mm = 7.37
"""Tissue scattering coefficient S."""
TISSUE_REFRACTIVE_INDEX = 1.36
"""Refractive index of the tissue."""
WAVELENGTH_nm = 473.0
"""Wavelength of the light; ChR2's action spectrum is 1 there (epsilon)."""
PHOTON_ENERGY_J = 6.63e-34 * 2.998e8 / (WAVELENGTH_nm * 1e-9)
"""h c / lambda with Cleo's constants (h = 6.63e-34 J s, c = 2.998e8 m/s)."""
FIBRE_DEPTH_mm = 0.05
"""Depth of each neuron below its fibre's tip, on the fibre's axis (as in the Cleo bridge)."""

OPSIN_DT_MS = 0.1
"""Integration step of the occupancies (Cleo's, the bridge's ``opsin_dt_ms``)."""
MAX_IRRADIANCE_mW_PER_mm2 = 1e6
"""The largest fibre-tip irradiance accepted (far above any tissue's tolerance)."""


def check_actuator(actuator: object, irradiance_mW_per_mm2: float) -> None:
    """Refuse an unknown actuator or an irradiance outside [0, max] (one ConfigError line)."""
    if not isinstance(actuator, str) or actuator not in ACTUATORS:
        raise ConfigError("actuator", f"must be one of {ACTUATORS}, got {actuator!r}",
                          label="Extensions.actuator")  # fmt: skip
    if not 0 <= irradiance_mW_per_mm2 <= MAX_IRRADIANCE_mW_PER_mm2:
        raise ConfigError(
            "light_irradiance_mW_per_mm2",
            f"must lie in [0, {MAX_IRRADIANCE_mW_PER_mm2:g}] mW/mm^2, got "
            f"{irradiance_mW_per_mm2:g}", label="Extensions.light_irradiance_mW_per_mm2",
        )  # fmt: skip


def fibre_transmittance(depth_mm: float = FIBRE_DEPTH_mm) -> float:
    """Fraction of the tip's irradiance that reaches a point ``depth_mm`` below the tip on
    the fibre's axis (Foutz et al. 2012 as Cleo's ``OpticFiber`` computes it, r = 0)."""
    spread = math.tan(math.asin(FIBRE_NUMERICAL_APERTURE / TISSUE_REFRACTIVE_INDEX))
    radius = FIBRE_RADIUS_mm + depth_mm * spread
    geometric = (FIBRE_RADIUS_mm / radius) ** 2
    gaussian = 1 / math.sqrt(2 * math.pi)  # exp(-2 (r / R(z))^2) at r = 0
    a = 1 + ABSORBANCE_PER_mm / SCATTERING_PER_mm
    b = math.sqrt(a**2 - 1)
    scattered = b * SCATTERING_PER_mm * depth_mm
    scattering = b / (a * math.sinh(scattered) + b * math.cosh(scattered))
    return gaussian * geometric * scattering


def photon_flux(irradiance_mW_per_mm2: float, depth_mm: float = FIBRE_DEPTH_mm) -> float:
    """Photons / (mm^2 s) at the neuron for a fibre-tip irradiance in mW/mm^2."""
    watts_per_mm2 = irradiance_mW_per_mm2 * 1e-3 * fibre_transmittance(depth_mm)
    return watts_per_mm2 / PHOTON_ENERGY_J


def light_rates(flux: float) -> np.ndarray:
    """[Ga1, Ga2, Gf, Gb] in 1/ms under a photon flux (photons / (mm^2 s)); the dark rates at 0."""
    lit = flux > 0
    h_p = flux**P_EXPONENT / (flux**P_EXPONENT + PHI_M_PER_mm2_s**P_EXPONENT) if lit else 0.0
    h_q = flux**Q_EXPONENT / (flux**Q_EXPONENT + PHI_M_PER_mm2_s**Q_EXPONENT) if lit else 0.0
    return np.array([K1_PER_ms * h_p, K2_PER_ms * h_p, KF_PER_ms * h_q + GF0_PER_ms,
                     KB_PER_ms * h_q + GB0_PER_ms])  # fmt: skip


def photocurrent_pA(o1, o2, voltage_mV):
    """The opsin current (pA, positive depolarises) of open fractions ``o1``, ``o2`` at
    potential ``voltage_mV``; scalars or arrays."""
    rectification = V1_mV * (1.0 - np.exp(-(voltage_mV - E_mV) / V0_mV))
    return -G0_nS * (o1 + GAMMA * o2) * rectification


def euler_substep(c1, o1, o2, rates, dt_ms):
    """One forward Euler step of the occupancies under ``rates`` ([Ga1, Ga2, Gf, Gb] in
    1/ms), every derivative from the old values: Cleo's scheme (Brian 2's ``euler``)."""
    ga1, ga2, gf, gb = rates
    c2 = 1.0 - c1 - o1 - o2
    d_c1 = GD1_PER_ms * o1 + GR0_PER_ms * c2 - ga1 * c1
    d_o1 = ga1 * c1 + gb * o2 - (GD1_PER_ms + gf) * o1
    d_o2 = ga2 * c2 + gf * o1 - (GD2_PER_ms + gb) * o2
    return c1 + dt_ms * d_c1, o1 + dt_ms * d_o1, o2 + dt_ms * d_o2


def euler_step_map(rates, dt_ms: float, substeps: int) -> np.ndarray:
    """[3, 4] the affine map of ``substeps`` :func:`euler_substep` steps under constant
    ``rates``: [C1, O1, O2] -> map[:, :3] @ [C1, O1, O2] + map[:, 3].

    Each Euler step is affine in the occupancies (C2 = 1 - C1 - O1 - O2), and the rates
    are constant within a 1 ms step (the light is on or off for all of it), so the ten
    sub-steps compose into one map: the same scheme, applied in 12 multiply-adds instead
    of ten dependent sub-steps (3x faster; results differ from the sub-steps in the last
    bits, ~1e-14 relative after an episode)."""
    points = np.vstack([np.zeros(3), np.eye(3)])  # the origin, then C1, O1, O2 alone
    for _ in range(substeps):
        points = np.stack(euler_substep(points[:, 0], points[:, 1], points[:, 2], rates,
                                        dt_ms), axis=1)  # fmt: skip
    return np.column_stack([(points[1:] - points[0]).T, points[0]])


def _current_pA(o1, o2, v):
    return -G0_nS * (o1 + GAMMA * o2) * (V1_mV * (1.0 - math.exp(-(v - E_mV) / V0_mV)))


current_pA = numba.njit(inline="always", cache=True, nogil=True)(_current_pA)


def _illuminate_kernel(
    c1,  # [B, n] float64 occupancy of C1, state, updated in place
    o1,  # [B, n] float64 occupancy of O1, state
    o2,  # [B, n] float64 occupancy of O2, state
    voltage,  # [B, n] float64: the potentials at the start of the step
    lit,  # [B] int64: the neuron under light this step, -1 none
    dark_map,  # [3, 4] euler_step_map of a step without light
    light_map,  # [3, 4] euler_step_map of a step under the pulse's light
    mV_per_pA,  # float: dt * 1 pA / C, a current's step in the potential
    out_mV,  # [B, 1, n] float64: gets (or, with accumulate, adds) each neuron's drive
    accumulate,  # bool: add to out_mV instead of overwriting it
):
    batch, n = c1.shape
    for b in range(batch):
        for j in range(n):
            x0, x1, x2 = c1[b, j], o1[b, j], o2[b, j]
            drive = mV_per_pA * current_pA(x1, x2, voltage[b, j])
            if accumulate:
                out_mV[b, 0, j] += drive
            else:
                out_mV[b, 0, j] = drive
            on = lit[b] == j
            # A resting opsin in the dark stays exactly at rest (the map's rounding would
            # move C1 by an ulp).
            if not on and x0 == 1.0 and x1 == 0.0 and x2 == 0.0:
                continue
            m = light_map if on else dark_map
            c1[b, j] = m[0, 0] * x0 + m[0, 1] * x1 + m[0, 2] * x2 + m[0, 3]
            o1[b, j] = m[1, 0] * x0 + m[1, 1] * x1 + m[1, 2] * x2 + m[1, 3]
            o2[b, j] = m[2, 0] * x0 + m[2, 1] * x1 + m[2, 2] * x2 + m[2, 3]


illuminate_kernel = numba.njit(cache=True, nogil=True)(_illuminate_kernel)


class OpsinActuator:
    """ChR2 in every neuron of a batch of networks, a fibre above each: the state an
    environment keeps across steps, and what one step's light does.

    ``irradiance_mW_per_mm2`` is the fibre tip's during a pulse; ``dt_ms`` the network's
    step (split into sub-steps of :data:`OPSIN_DT_MS`); ``capacitance_pF`` turns the
    current into mV per step.
    """

    def __init__(self, batch: int, n_neurons: int, irradiance_mW_per_mm2: float,
                 dt_ms: float, capacitance_pF: float) -> None:  # fmt: skip
        shape = (batch, n_neurons)
        self.c1 = np.ones(shape)
        self.o1 = np.zeros(shape)
        self.o2 = np.zeros(shape)
        self.substeps = max(1, round(dt_ms / OPSIN_DT_MS))
        self.substep_ms = dt_ms / self.substeps
        self.mV_per_pA = dt_ms / capacitance_pF
        self.flux = photon_flux(irradiance_mW_per_mm2)
        self.dark_map = euler_step_map(light_rates(0.0), self.substep_ms, self.substeps)
        self.light_map = euler_step_map(light_rates(self.flux), self.substep_ms, self.substeps)
        self.dark = np.full((batch, 1), -1, dtype=np.int64)  # the kernel's actions: no pulse
        self.accumulate = False  # whether illuminate adds its drive to the buffer's input

    @classmethod
    def for_environment(cls, extensions, params, batch: int, n_neurons: int):
        """The opsins of ``batch`` networks at rest for an environment's ``Extensions``
        and ``NeuronParams``, or None when its actuator is the paper's pulse."""
        if not extensions.lit:
            return None
        actuator = cls(batch, n_neurons, extensions.light_irradiance_mW_per_mm2, params.dt_ms,
                       params.capacitance_pF)  # fmt: skip
        # The background input (drawn into the same buffer first) stays; the drive adds.
        actuator.accumulate = extensions.background_rate > 0
        return actuator

    def reset(self, which: np.ndarray | None = None) -> None:
        """Put the opsins of the networks selected by the [B] mask ``which`` (all: None)
        back at rest: every channel closed in C1."""
        rows = slice(None) if which is None else which
        self.c1[rows] = 1.0
        self.o1[rows] = 0.0
        self.o2[rows] = 0.0

    def illuminate(
        self, voltage_mV: np.ndarray, actions: np.ndarray, out_mV: np.ndarray
    ) -> np.ndarray:
        """One step: write each neuron's opsin drive (mV, [B, 1, n]) for the step that
        starts at ``voltage_mV`` [B, n] into ``out_mV`` (added with ``accumulate``), then
        advance the occupancies through the step, the neuron ``actions[b, 0]`` (-1: none)
        of network b under light. Returns the actions the simulator takes instead:
        none, the light being the only stimulus."""
        illuminate_kernel(self.c1, self.o1, self.o2, voltage_mV, actions[:, 0], self.dark_map,
                          self.light_map, self.mV_per_pA, out_mV, self.accumulate)  # fmt: skip
        return self.dark

    @property
    def c2(self) -> np.ndarray:
        """[B, n] occupancy of C2, 1 - C1 - O1 - O2."""
        return 1.0 - self.c1 - self.o1 - self.o2
