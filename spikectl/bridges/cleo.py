"""spikectl's controllers in Cleo: a context's network in Brian 2, controlled in closed loop.

:class:`CleoLoop` builds the network of a :class:`~spikectl.contexts.ContextSet`'s size in
Brian 2 — the leaky integrate-and-fire neurons with short-term depression of
docs/model.md, step for step — and plays any spikectl controller (``reset()``,
``act(observation, info)``: a trained network, a compiled policy, identify-and-plan, the
oracle) on it through Cleo's ``CLSimulator``: Cleo's recorder gives the measurements, an
IOProcessor (:class:`~spikectl.bridges.cleo_devices.ControllerProcessor`) turns them into
the controller's observation and its action into a stimulation, and the return is
computed from the target's spikes as the environment computes it.

:class:`CleoSetting` chooses how realistic the loop is. Its defaults (:data:`IDEAL`) are
spikectl's environment: the membrane potentials observed exactly, the paper's 1 200 pA
pulse on one neuron for one 1 ms step, no latency — every action and return then equal
``NeuronControlEnv``'s on the same contexts (tests/test_bridge_cleo.py). The other
settings swap in Cleo's devices: ChR2 (four-state) under an optic fibre per neuron
instead of the pulse, the loop latency of Cleo's ``LatencyIOProcessor``, and Gaussian
noise on the measured potentials, and spikes-only sensing with Cleo's ground-truth spike
recorder.

How the model maps onto Brian 2 (dt = 1 ms, Euler, as a controller step): a spike at
step k sets the neuron's potential to V_r and holds it for ``refractory_steps`` steps,
which is Brian's ``refractory = (refractory_steps + 1) * dt`` (Brian counts the spike's
own step); a spike releases when at least ``min_release_interval_steps`` steps have passed
since the neuron's last release (``since``, counted at the start of each step as the
kernel counts it), and a release adds ``w_ij * w_in`` to the postsynaptic current of the
*next* step (``I_next``, moved to ``I_syn`` at the start of the step). The potential the
controller sees is the one after integration and before reset (``v_seen``).

Brian 2 keeps its settings in globals: building a loop sets ``prefs.codegen.target`` to
``"numpy"`` (no compiler needed) and ``defaultclock.dt`` to the step of Cleo's opsin
and light objects, which run on the default clock (0.1 ms with ChR2, else 1 ms; the
network keeps its own 1 ms clock), before it builds and before each episode.

Needs the ``cleo`` extra (cleosim, Brian 2): ``pip install -c constraints-cleo.txt
"spikectl[cleo]"``; without it, importing this module raises
:class:`~spikectl.config_errors.MissingExtraError`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

# cleo_devices imports Cleo and Brian 2 behind the extra's one-line MissingExtraError.
from spikectl.bridges.cleo_devices import (
    ControllerProcessor,
    EpisodeSpikeRecorder,
    PotentialRecorder,
    PulseStimulator,
    b2,
    cleo,
)
from spikectl.config_errors import ConfigError
from spikectl.contexts import ContextSet
from spikectl.envs.controller import Controller
from spikectl.envs.env_support import ContextTables
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.kernel import SINCE_RELEASE_CAP
from spikectl.neuron.params import NeuronParams

SENSING_MODES = ("potentials", "spikes")
"""``potentials``: every neuron's membrane potential (ideal); ``spikes``: spikes only."""

ACTUATIONS = ("pulse", "chr2")
"""``pulse``: the paper's current pulse (ideal); ``chr2``: Cleo's four-state ChR2 and light."""

DEFAULT_IRRADIANCE_mW_PER_mm2 = 5.0
"""Irradiance at the fibre tip of one 1 ms light pulse with ChR2: the lowest of 1, 2, 5,
10, 20, 50 mW/mm2 at which one pulse makes a resting neuron spike at the next step (the
channel closes over ~10 ms, so it spikes again 3 steps later; docs/cleo.md)."""

NEURON_SPACING_mm = 5.0
"""Distance between neighbouring neurons with ChR2: each fibre lights its own neuron only."""

FIBRE_DEPTH_mm = 0.05
"""Depth of each neuron below its fibre's tip, on the fibre's axis."""


@dataclass(frozen=True)
class CleoSetting:
    """How realistic Cleo's closed loop is; the defaults are spikectl's environment."""

    actuation: str = "pulse"
    """``pulse``: the paper's stimulus current for one step on the chosen neuron;
    ``chr2``: a 1 ms light pulse from an optic fibre (473 nm) above the chosen neuron,
    every neuron expressing Cleo's four-state ChR2."""
    latency_ms: int = 0
    """Loop latency: an action computed from the measurement at step k is applied at step
    k + latency_ms (Cleo's LatencyIOProcessor); the first steps stimulate nothing."""
    noise_mV: float = 0.0
    """Standard deviation of Gaussian noise on each measured potential, in mV."""
    noise_seed: int = 0
    """Seed of the measurement noise (episode of context c: generator seeded [seed, c])."""
    irradiance_mW_per_mm2: float = DEFAULT_IRRADIANCE_mW_PER_mm2
    """Irradiance at the fibre tip of a light pulse (``chr2``)."""
    opsin_dt_ms: float = 0.1
    """Integration step of the opsin and light (``chr2``): ChR2's fastest rate (4.15/ms)
    makes Euler steps of 1 ms unstable."""
    sensing: str = "potentials"
    """``potentials``: the recorder measures every membrane potential; ``spikes``: Cleo's
    ground-truth spike recorder, and the controller observes spikes only (spikectl's
    ``extensions={"sensing": "spikes"}``)."""

    def __post_init__(self) -> None:
        if self.actuation not in ACTUATIONS:
            raise ConfigError("actuation", f"must be one of {ACTUATIONS}, got {self.actuation!r}")
        if isinstance(self.latency_ms, bool) or not isinstance(self.latency_ms, (int, np.integer)):
            raise ConfigError("latency_ms", f"must be whole ms, got {self.latency_ms!r}")
        if self.latency_ms < 0:
            raise ConfigError("latency_ms", f"must be >= 0, got {self.latency_ms}")
        for name in ("noise_mV", "irradiance_mW_per_mm2"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ConfigError(name, f"must be finite and >= 0, got {value!r}")
        if self.sensing not in SENSING_MODES:
            raise ConfigError("sensing", f"must be one of {SENSING_MODES}, got {self.sensing!r}")
        if self.sensing == "spikes" and self.noise_mV:
            raise ConfigError("noise_mV", "must be 0 with sensing 'spikes' (no potential is "
                              "measured)")  # fmt: skip
        if not 0 < self.opsin_dt_ms <= 1.0 or not float(1.0 / self.opsin_dt_ms).is_integer():
            raise ConfigError(
                "opsin_dt_ms", f"must divide 1 ms (0.1, 0.05, ...), got {self.opsin_dt_ms!r}"
            )


def matching_extensions(setting: CleoSetting) -> Extensions:
    """The spikectl extensions of the loop ``setting`` models: ``latency_ms`` as
    ``latency_steps`` (steps are 1 ms), the ChR2 actuation at the same irradiance,
    spikes-only sensing, and the measurement noise's sigma. Controllers made for them
    (``load_controller(name, env=NeuronControlEnv(extensions=...))``) plan the loop they
    play; without noise, spikectl's environment with them plays as Cleo does, action for
    action (the noise's draws differ: Cleo's generator is seeded per context)."""
    light = {"light_irradiance_mW_per_mm2": float(setting.irradiance_mW_per_mm2)}
    return Extensions(
        latency_steps=int(setting.latency_ms),
        actuator=setting.actuation,
        sensing=setting.sensing,
        observation_noise_mV=float(setting.noise_mV),
        **(light if setting.actuation == "chr2" else {}),
    )


IDEAL = CleoSetting()

SETTINGS: dict[str, CleoSetting] = {
    "ideal": IDEAL,
    "latency1": CleoSetting(latency_ms=1),
    "latency2": CleoSetting(latency_ms=2),
    "latency3": CleoSetting(latency_ms=3),
    "noise1": CleoSetting(noise_mV=1.0),
    "chr2": CleoSetting(actuation="chr2"),
    "chr2-latency2-noise1": CleoSetting(actuation="chr2", latency_ms=2, noise_mV=1.0),
    "spikes-only": CleoSetting(sensing="spikes"),
    "chr2-latency2-spikes": CleoSetting(actuation="chr2", latency_ms=2, sensing="spikes"),
}
"""The named settings of docs/cleo.md's table."""


@dataclass(frozen=True)
class CleoEpisode:
    """One episode of a controller in Cleo."""

    actions: np.ndarray
    """[N] int64: the controller's action at each step (applied latency_ms steps later)."""
    target_spikes: np.ndarray
    """[N] bool: whether the target spiked at each step."""
    rewards: np.ndarray
    """[N] float64: the environment's reward of each step."""
    total: float
    """The return: the rewards summed in step order, as the environment sums them."""
    seconds: float
    """Wall-clock seconds of the episode (Brian's run, Cleo's loop and the controller)."""


class CleoLoop:
    """The networks of ``contexts`` in Brian 2 under Cleo, played by spikectl controllers.

    One Brian network of the set's size is built once; each episode restores it to rest
    (``CLSimulator.reset``), loads the context's weights and target, and runs the
    episode's N ms with the controller in the loop. Contexts with extensions (hidden or
    heterogeneous neurons) are refused: the bridge models the paper's network.
    """

    def __init__(self, contexts: ContextSet, setting: CleoSetting = IDEAL) -> None:
        if not isinstance(contexts, ContextSet):
            raise TypeError(f"contexts must be a ContextSet, got {type(contexts).__name__}")
        if not isinstance(setting, CleoSetting):
            raise TypeError(f"setting must be a CleoSetting, got {type(setting).__name__}")
        if any(c.hidden is not None or c.heterogeneity is not None for c in contexts):
            raise ValueError(
                "the Cleo bridge models the paper's network: contexts with hidden or "
                "heterogeneous neurons are not supported"
            )
        self.contexts, self.setting = contexts, setting
        self.params: NeuronParams = contexts.params
        self.n_neurons, self.episode_length = contexts.n_neurons, contexts.episode_length
        self._tables = ContextTables.build(list(contexts), False, self.params)
        self._build()

    def _build(self) -> None:
        b2.prefs.codegen.target = "numpy"
        self._set_default_clock()
        setting, params, n = self.setting, self.params, self.n_neurons
        step = params.dt_ms * b2.ms
        self._step = step
        self.neurons, self.synapses = brian_network(n, params)
        self._spikes = b2.SpikeMonitor(self.neurons, name="spikectl_spikes")
        self.simulator = cleo.CLSimulator(b2.Network(self.neurons, self.synapses, self._spikes))
        spikes_only = setting.sensing == "spikes"
        if spikes_only:
            self.recorder = EpisodeSpikeRecorder(name="spikes")
        else:
            self.recorder = PotentialRecorder(name="potentials", noise_mV=setting.noise_mV)
        self.simulator.inject(self.recorder, self.neurons)
        if setting.actuation == "pulse":
            stimulator = PulseStimulator(name="pulse", current_pA=params.stimulus_current_pA)
            self.simulator.inject(stimulator, self.neurons)
            actuate = stimulator.signal
        else:
            actuate = self._inject_chr2()
        self.processor = ControllerProcessor(
            sample_period=step, latency_ms=setting.latency_ms, actuate=actuate,
            recorder=self.recorder.name, spikes_only=spikes_only,
        )  # fmt: skip
        self.simulator.set_io_processor(self.processor, communication_period=step)

    def _set_default_clock(self) -> None:
        # Cleo's opsin and light run on Brian's default clock, a global: each loop sets
        # it before it builds and before each episode, so that loops of different
        # settings can share a process.
        chr2 = self.setting.actuation == "chr2"
        b2.defaultclock.dt = (self.setting.opsin_dt_ms if chr2 else self.params.dt_ms) * b2.ms

    def _inject_chr2(self):
        n = self.n_neurons
        x = np.arange(n) * NEURON_SPACING_mm
        cleo.coords.assign_xyz(self.neurons, x, np.zeros(n), np.full(n, FIBRE_DEPTH_mm),
                               unit=b2.mm)  # fmt: skip
        opsin = cleo.opto.chr2_4s()
        fibres = np.stack([x, np.zeros(n), np.zeros(n)], axis=1) * b2.mm
        light = cleo.light.Light(
            light_model=cleo.light.fiber473nm(), coords=fibres, name="light"
        )
        self.simulator.inject(opsin, self.neurons)
        self.simulator.inject(light, self.neurons)
        irradiance = self.setting.irradiance_mW_per_mm2

        def actuate(action: int) -> dict[str, Any]:
            values = np.zeros(n)
            if action >= 0:
                values[action] = irradiance
            return {"light": values * b2.mwatt / b2.mm2}

        return actuate

    def play(self, controller: Controller, context: int) -> CleoEpisode:
        """One episode of ``controller`` (reset first) on context index ``context``."""
        if not isinstance(controller, Controller):
            raise TypeError(
                f"{type(controller).__name__} is not a controller: it needs reset() and "
                "act(observation, info) -> int"
            )
        row = int(context)
        if not 0 <= row < len(self.contexts):
            raise IndexError(f"context {context} is out of range 0..{len(self.contexts) - 1}")
        started = time.perf_counter()
        self._set_default_clock()
        self.simulator.reset()
        tables = self._tables
        weights = tables.weights[row]
        self.synapses.w[:] = weights[np.asarray(self.synapses.i), np.asarray(self.synapses.j)]
        if isinstance(self.recorder, PotentialRecorder):
            self.recorder.rng = np.random.default_rng([self.setting.noise_seed, row])
        target = int(tables.targets[row])
        self.processor.begin(
            controller, target, tables.patterns[row], tables.legal[row], row, self.params
        )
        controller.reset()
        self.simulator.run(self.episode_length * self._step)
        spiked = np.zeros(self.episode_length, dtype=bool)
        steps = np.rint(np.asarray(self._spikes.t / self._step)).astype(np.int64)
        spiked[steps[np.asarray(self._spikes.i) == target]] = True
        rewards = np.where(spiked, tables.reward_if_spike[row], tables.reward_if_silent[row])
        total = 0.0
        for reward in rewards.tolist():
            total += reward
        return CleoEpisode(
            actions=np.array(self.processor.actions, dtype=np.int64),
            target_spikes=spiked,
            rewards=rewards,
            total=total,
            seconds=time.perf_counter() - started,
        )

    def play_all(self, controller: Controller, contexts=None) -> list[CleoEpisode]:
        """An episode of ``controller`` on each context index (default: every one)."""
        indices = range(len(self.contexts)) if contexts is None else contexts
        return [self.play(controller, index) for index in indices]


NEURON_MODEL = """
dv/dt = -(v - v_rest) / tau_m + (I_syn + I_stim + Iopto) / C : volt (unless refractory)
I_syn : amp
I_next : amp
I_stim : amp
Iopto : amp
v_seen : volt
since : integer
"""
"""The membrane equation of docs/model.md; ``I_syn`` holds the releases of the previous
step, ``I_next`` collects this step's; ``since`` counts steps since the last release."""


def brian_network(n: int, params: NeuronParams):
    """(NeuronGroup, Synapses): ``n`` neurons of ``params`` at rest, all-to-all synapses
    with weight ``w`` (0 until a context's weights are loaded), on a 1-step clock."""
    step = params.dt_ms * b2.ms
    namespace = {
        "v_rest": params.v_rest_mV * b2.mV,
        "v_spike": params.v_spike_mV * b2.mV,
        "tau_m": params.membrane_time_constant_ms * b2.ms,
        "C": params.capacitance_pF * b2.pF,
        "w_in": params.synaptic_current_pA * b2.pA,
        "release_after": params.min_release_interval_steps,
        "since_cap": SINCE_RELEASE_CAP,
    }
    neurons = b2.NeuronGroup(
        n, NEURON_MODEL, threshold="v >= v_spike",
        reset="v = v_rest\nsince = since * int(since < release_after)",
        refractory=(params.refractory_steps + 1) * step, method="euler", dt=step,
        namespace=namespace, name="spikectl_neurons",
    )  # fmt: skip
    neurons.v = params.v_rest_mV * b2.mV
    neurons.v_seen = params.v_rest_mV * b2.mV
    neurons.since = SINCE_RELEASE_CAP
    neurons.run_regularly(
        "since = since + int(since < since_cap)\nI_syn = I_next\nI_next = 0*amp",
        dt=step, when="start", name="spikectl_step_start",
    )  # fmt: skip
    neurons.run_regularly("v_seen = v", dt=step, when="before_thresholds",
                          name="spikectl_observe")  # fmt: skip
    synapses = b2.Synapses(
        neurons, neurons, model="w : 1",
        on_pre="I_next_post += w * w_in * int(since_pre >= release_after)",
        dt=step, namespace=namespace, name="spikectl_synapses",
    )  # fmt: skip
    synapses.connect()
    return neurons, synapses


__all__ = ["ACTUATIONS", "IDEAL", "SETTINGS", "CleoEpisode", "CleoLoop", "CleoSetting",
           "brian_network"]  # fmt: skip
