"""Each neuron's threshold and leak, learned from what it does (heterogeneous neurons).

With heterogeneous neurons (``Extensions.threshold_spread``, ``time_constant_spread``)
every neuron has its own threshold, V_r + (V_th - V_r)(1 + s u) with u uniform on
[-1, 1), and its own membrane time constant. One release from rest lifts a neuron by
about w_in = 20 mV, onto the thresholds' range (-52 to -48 mV at s = 0.1): whether it
spikes is the neuron's own threshold, and
:class:`~spikectl.planning.identify.ObservedState`, which reads a spike at the paper's
-50 mV, misreads it, and so does a planner that simulates the paper's neurons.

:class:`NeuronTracker` keeps, for each neuron i, the interval (low_i, high_i] that its
threshold theta_i (V_th less the kernel's tolerance) lies in: the prior's range at
first; a neuron seen to spike at V has theta_i <= V, one seen not to, theta_i > V. A
potential inside the interval is read provisionally (a spike from its middle on), and
the next observation settles it: a neuron that spiked is held at V_r for its refractory
step, one that did not has moved on from V (it lands on V_r exactly only by
coincidence). The state is corrected then (potential, refractoriness, release) before
that step's evidence is computed, so the identification sees only settled reads. Its
leak dt / tau_i is measured exactly on a step on which nothing drove it (no release
anywhere, no stimulus, not refractory):

    V_t - V_r = (1 - leak_i) (V_{t-1} - V_r).

:meth:`NeuronTracker.neurons` gives the planner the kernel's per-neuron parameters
(the middle of each interval, the measured leaks).
"""

from __future__ import annotations

import numpy as np

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning.identify import ObservedState

MIN_DECAY_MV = 0.5
"""A leak is measured only from a potential at least this far from V_r (mV): nearer,
the float32 observation's rounding is a larger part of the decay."""


class NeuronTracker(ObservedState):
    """:class:`ObservedState` with each neuron's threshold and leak learned on the way.

    Args:
        n_neurons, params: as :class:`ObservedState`.
        extensions: the environment's, whose ``threshold_spread`` sets the thresholds'
            prior range (uniform on V_r + (V_th - V_r)(1 +- spread)).
    """

    def __init__(self, n_neurons: int, params: NeuronParams, extensions: Extensions) -> None:
        if params.refractory_steps < 1:
            raise ValueError(
                "NeuronTracker settles a spike by the refractory step after it: "
                f"params.refractory_steps must be >= 1, got {params.refractory_steps}"
            )
        super().__init__(n_neurons, params, 0.0)
        distance = params.v_threshold_mV - params.v_rest_mV
        spread = extensions.threshold_spread
        theta = params.v_rest_mV + distance - params.threshold_tolerance_mV
        # theta_i in (low_i, high_i]: the prior's range, a hair wider below.
        self.low = np.full(n_neurons, theta - distance * spread - 1e-9)
        self.high = np.full(n_neurons, theta + distance * spread)
        self.leak = np.full(n_neurons, params.leak_per_step)
        self._unsettled = np.zeros(n_neurons, dtype=bool)  # read provisionally last step
        self._last_voltage = np.zeros(n_neurons)  # what each neuron showed then
        self._planning: np.ndarray | None = None  # neurons(), until an interval or leak moves

    def neurons(self) -> np.ndarray:
        """[1, 2, n] kernel parameters to plan with: each threshold at the middle of its
        interval, each leak as measured (the paper's until measured)."""
        if self._planning is None:
            middle = 0.5 * (self.low + self.high)
            self._planning = np.ascontiguousarray(np.stack([middle, self.leak])[None])
        return self._planning

    def observe(self, voltage: np.ndarray, action: int) -> tuple[np.ndarray, ...]:
        """As :meth:`ObservedState.observe`, after settling last step's provisional
        reads by this observation and measuring the leaks it shows."""
        voltage = np.asarray(voltage, dtype=np.float64)
        self._settle(voltage)
        self._measure_leaks(voltage, action)
        return super().observe(voltage, action)

    def _leak(self) -> np.ndarray:
        return self.leak

    def _read(self, voltage: np.ndarray, observed: np.ndarray) -> np.ndarray:
        """Certain where the potential is outside the threshold's interval; inside it, a
        spike from the middle on, to be settled by the next observation."""
        unsettled = observed & (voltage > self.low) & (voltage < self.high)
        middle = 0.5 * (self.low + self.high)
        self._unsettled, self._last_voltage = unsettled, voltage
        return observed & ((voltage >= self.high) | (unsettled & (voltage >= middle)))

    def _measure_leaks(self, voltage: np.ndarray, action: int) -> None:
        """Each leak from this step where nothing drove the neuron: no release anywhere
        (no synaptic input), no stimulus, not refractory, a potential off V_r."""
        state, params = self.state, self.params
        if state.released[0].any():
            return
        before = state.voltage_mV[0]
        decay = before - params.v_rest_mV
        free = (state.refractory_left[0] == 0) & (np.abs(decay) >= MIN_DECAY_MV)
        free &= voltage < self.high  # not (certainly) a spike
        if action != DO_NOTHING:
            free[action] = False
        if free.any():
            self.leak = np.where(free, (before - voltage) / np.where(free, decay, 1.0), self.leak)
            self._planning = None

    def _settle(self, voltage: np.ndarray) -> None:
        """Correct last step's provisional reads by this step's potentials: a neuron that
        spiked shows V_r exactly (held refractory); narrow its threshold's interval."""
        if not self._unsettled.any():
            return
        truly = self._unsettled & (voltage == self.params.v_rest_mV)
        shown = self._last_voltage
        self.high = np.where(truly, np.minimum(self.high, shown), self.high)
        self.low = np.where(self._unsettled & ~truly, np.maximum(self.low, shown), self.low)
        for neuron in np.flatnonzero(self._unsettled & (truly != self.spiked)):
            self._correct(int(neuron), bool(truly[neuron]), float(shown[neuron]))
        self._unsettled = np.zeros_like(self._unsettled)
        self._planning = None


def tracks_neurons(extensions: Extensions | None, noise_mV: float, params: NeuronParams) -> bool:
    """Whether identify-and-plan learns each neuron's threshold and leak: where neurons
    differ in them, the potentials are seen without noise and a spike is followed by a
    refractory step (a read is settled by V_r seen exactly)."""
    if extensions is None or noise_mV > 0 or extensions.observation_noise_mV > 0:
        return False
    if params.refractory_steps < 1:
        return False
    return extensions.threshold_spread > 0 or extensions.time_constant_spread > 0
