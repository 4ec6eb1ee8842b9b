"""Cleo's side of the bridge: the recorder, the ideal pulse and the IOProcessor that plays
a spikectl controller (used by :mod:`spikectl.bridges.cleo`; needs the ``cleo`` extra)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from spikectl.config_errors import MissingExtraError

try:  # the one guard of the Cleo extra: spikectl.bridges.cleo imports through here
    import brian2 as b2
    import cleo  # noqa: F401  (spikectl.bridges.cleo uses it from here)
    from attrs import define, field
    from cleo.base import Recorder, Stimulator
    from cleo.ioproc import LatencyIOProcessor
    from cleo.recorders import GroundTruthSpikeRecorder
except ImportError as _error:
    raise MissingExtraError(
        f"spikectl.bridges.cleo needs Cleo and Brian 2 ({_error}): "
        'pip install -c constraints-cleo.txt "spikectl[cleo]" (docs/cleo.md)'
    ) from None

from spikectl.envs.controller import Controller
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.envs.sensing import SPIKES_KEY
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING

VOLT_PER_mV = 1e-3
AMPERE_PER_pA = 1e-12


@define(eq=False)
class PotentialRecorder(Recorder):
    """Ideal voltage sensing: each neuron's potential after integration and before reset
    (what spikectl observes), in mV, plus Gaussian noise of ``noise_mV`` where set; and
    the step's true spikes (potential at or above V_th less the tolerance)."""

    noise_mV: float = field(default=0.0, kw_only=True)
    rng: np.random.Generator = field(factory=lambda: np.random.default_rng(0), kw_only=True)
    neuron_group: Any = field(default=None, init=False)

    def connect_to_neuron_group(self, neuron_group, **kwparams) -> None:
        self.neuron_group = neuron_group

    def get_state(self) -> dict[str, np.ndarray]:
        voltage = np.asarray(self.neuron_group.v_seen_, dtype=np.float64) / VOLT_PER_mV
        threshold = self.neuron_group.namespace["v_spike"] / b2.mV
        spikes = voltage >= threshold
        if self.noise_mV > 0:
            voltage = voltage + self.rng.normal(0.0, self.noise_mV, voltage.shape)
        return {"voltage_mV": voltage, "spikes": spikes}


@define(eq=False)
class EpisodeSpikeRecorder(GroundTruthSpikeRecorder):
    """Spike sensing: Cleo's ground-truth spike recorder (each neuron's spikes since the
    last sample, from a Brian SpikeMonitor), counting from zero again after each
    ``CLSimulator.reset`` (Cleo's own keeps its count across resets, while the reset
    empties the monitor)."""

    def reset(self, **kwargs) -> None:
        self._num_spikes_seen = 0


@define(eq=False)
class PulseStimulator(Stimulator):
    """Ideal actuation: the control signal is an action (a neuron, or -1 for none), and
    that neuron receives ``current_pA`` until the next signal (one step in the loop)."""

    current_pA: float = field(kw_only=True)
    neuron_group: Any = field(default=None, init=False)

    def connect_to_neuron_group(self, neuron_group, **kwparams) -> None:
        self.neuron_group = neuron_group
        self.update(DO_NOTHING)

    def update(self, ctrl_signal: int) -> None:
        super().update(ctrl_signal)
        if self.neuron_group is None:
            return
        current = np.zeros(len(self.neuron_group))
        if ctrl_signal >= 0:
            current[int(ctrl_signal)] = self.current_pA * AMPERE_PER_pA
        self.neuron_group.I_stim_ = current

    def reset(self, **kwargs) -> None:
        self._init_saved_vars()
        self.update(DO_NOTHING)

    def signal(self, action: int) -> dict[str, int]:
        """The control signals that apply ``action``."""
        return {self.name: int(action)}


class ControllerProcessor(LatencyIOProcessor):
    """Cleo's IOProcessor around a spikectl controller.

    At each 1 ms sample it turns the recorder's measurement into the observation
    ``NeuronControlEnv`` would give (voltage float32 in mV, or with ``spikes_only`` the
    spike recorder's spikes as int8 ``spikes``; target, pattern, step,
    last action, and with latency the actions in flight, as ``extensions={"latency_steps":
    latency_ms}`` gives them) and ``info`` (action mask, context index, and after step 0
    the previous step's spikes), asks the controller for an action, and returns the
    control signals that apply it (``actuate``), delivered ``latency`` later by
    LatencyIOProcessor.
    """

    def __init__(self, sample_period, latency_ms: int, actuate: Callable[[int], dict],
                 recorder: str, spikes_only: bool = False) -> None:  # fmt: skip
        super().__init__(sample_period)
        self.latency_ms = latency_ms
        self.actuate = actuate
        self.recorder = recorder
        self.spikes_only = spikes_only
        self.controller: Controller | None = None
        self.actions: list[int] = []

    def begin(self, controller: Controller, target: int, pattern: np.ndarray, legal: np.ndarray,
              context_index: int, params: NeuronParams) -> None:  # fmt: skip
        """Start an episode of ``controller`` on a context (after the simulator's reset)."""
        self.controller = controller
        self.target, self.pattern, self.legal = target, pattern, legal
        self.context_index = context_index
        self.actions = []

    def process(self, state_dict: dict, t_samp) -> tuple[dict, Any]:
        step = len(self.actions)
        measured = state_dict[self.recorder]
        if self.spikes_only:  # the spike recorder's counts since the last sample
            measured = {"spikes": np.asarray(measured) > 0}
            sensed = {SPIKES_KEY: measured["spikes"].astype(np.int8)}
        else:
            sensed = {"voltage": measured["voltage_mV"].astype(np.float32)}
        observation = {
            **sensed,
            "target": self.target,
            "pattern": self.pattern.copy(),
            "step": step,
            "last_action": self.actions[-1] if self.actions else DO_NOTHING,
        }
        if self.latency_ms:  # chosen, not yet delivered: the last latency_ms, oldest first
            in_flight = [DO_NOTHING] * self.latency_ms + self.actions[-self.latency_ms :]
            observation[IN_FLIGHT_KEY] = np.array(in_flight[-self.latency_ms :], dtype=np.int64)
        info: dict[str, Any] = {
            "action_mask": self.legal.copy(),
            "context_index": self.context_index,
        }
        if step > 0:
            info["spikes"] = measured["spikes"].copy()
            info["target_spiked"] = bool(measured["spikes"][self.target])
        action = int(self.controller.act(observation, info))
        if not (DO_NOTHING <= action < len(self.legal) - 1 and self.legal[action + 1]):
            raise ValueError(
                f"the controller chose action {action} at step {step}, which is not legal "
                f"(-1 or a neuron in 0..{len(self.legal) - 2} other than the target {self.target})"
            )
        self.actions.append(action)
        # Cleo compares the output time with round(t / ms, 6) * ms: rounded alike, an
        # output lands exactly latency steps later (t_samp + latency may be 1 ulp late,
        # which would hold it, and every output after it, for one more step).
        return self.actuate(action), round(float(t_samp / b2.ms + self.latency_ms), 6) * b2.ms
