"""The batched simulator of SPEC section 1: LIF neurons with short-term depression.

There is one implementation of the dynamics, the Numba kernel ``_advance``. It moves
a batch of independent networks forward by any number of 1 ms steps and writes what
an observer sees. ``simulate`` runs whole action sequences through it; ``advance``
runs one step (or a few) of a :class:`SimulatorState` and is what the environments
call. With ``NUMBA_DISABLE_JIT=1`` the same code runs as plain Python.

Order inside step t, given action a_t (SPEC 1):

1. I_syn,j = w_in * sum_i G[i, j] * released_i(t-1)      (one-step synaptic delay)
2. I_ext,j = w_e if a_t == j else 0
3. refractory neurons are held at V_r and ignore input; the others take one Euler step
   V += dt * (-(V - V_r) / (R C) + (I_ext + I_syn) / C)
4. spiked = V >= V_th - tolerance; the observation is V now (after integration,
   before reset); spiking neurons are reset to V_r and become refractory
5. a spike releases vesicles iff p_r (1 - exp(-(t - t_r) / tau_R)) >= 0.5, i.e. iff at
   least ``params.min_release_interval_steps`` steps passed since the last release.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from spikectl.params import NeuronParams

DO_NOTHING = -1
"""The action that stimulates no neuron."""

# Batches at least this large are split over threads; below it the thread start-up
# costs more than it saves (measured in benchmarks/bench_simulator.py).
PARALLEL_MIN_BATCH = 256

# steps_since_release saturates here, far beyond any release interval but below
# NEVER_RELEASES, so "no release yet" (t_r = -inf) stays ready to release.
_SINCE_RELEASE_CAP = 2**30


def _advance_kernel(
    weights,  # [W, n, n] int8, W == 1 (shared) or W == B
    actions,  # [B, T] int64, -1 = do nothing
    voltage,  # [B, n] float64, state, updated in place
    refractory_left,  # [B, n] int32, state
    steps_since_release,  # [B, n] int32, state
    released,  # [B, n] bool, state: released at the previous step
    v_rest,
    v_spike,  # threshold minus tolerance
    leak_per_step,  # dt / (R C)
    stimulus_step_mV,  # dt * w_e / C
    synaptic_step_mV,  # dt * w_in / C
    refractory_steps,
    min_release_interval,
    out_voltage,  # [B, T, n] float64
    out_spikes,  # [B, T, n] bool
):
    batch, horizon = actions.shape
    n = voltage.shape[1]
    shared_weights = weights.shape[0] == 1
    for b in numba.prange(batch):
        w = weights[0] if shared_weights else weights[b]
        # Thread-private copies of this network's state: rows of neighbouring networks
        # share cache lines, and writing them from two threads halves the throughput.
        v_b = voltage[b].copy()
        refractory_b = refractory_left[b].copy()
        since_b = steps_since_release[b].copy()
        released_b = released[b].copy()
        synaptic_input = np.empty(n)
        for t in range(horizon):
            synaptic_input[:] = 0.0
            for i in range(n):
                if released_b[i]:
                    for j in range(n):
                        synaptic_input[j] += w[i, j]
            action = actions[b, t]
            for j in range(n):
                since = since_b[j]
                if since < _SINCE_RELEASE_CAP:
                    since += 1
                spiked = False
                if refractory_b[j] > 0:
                    refractory_b[j] -= 1
                    v = v_rest
                else:
                    v = v_b[j]
                    drive = synaptic_step_mV * synaptic_input[j]
                    if action == j:
                        drive += stimulus_step_mV
                    v = v + (-(v - v_rest) * leak_per_step + drive)
                    spiked = v >= v_spike
                out_voltage[b, t, j] = v
                out_spikes[b, t, j] = spiked
                release = False
                if spiked:
                    v = v_rest
                    refractory_b[j] = refractory_steps
                    if since >= min_release_interval:
                        release = True
                        since = 0
                v_b[j] = v
                since_b[j] = since
                released_b[j] = release
        voltage[b] = v_b
        refractory_left[b] = refractory_b
        steps_since_release[b] = since_b
        released[b] = released_b


# One kernel, compiled twice: serially for small batches (the single environment)
# and with threads over the batch for large ones. Both give identical results.
# The parallel build is not cached: loaded from Numba's cache it ran at half speed
# (numba 0.68, measured with benchmarks/bench_simulator.py).
_advance_serial = numba.njit(cache=True, nogil=True)(_advance_kernel)
_advance_parallel = numba.njit(nogil=True, parallel=True)(_advance_kernel)


@dataclass
class SimulatorState:
    """The changing state of a batch of networks; the parameters live elsewhere."""

    voltage_mV: np.ndarray
    """[B, n] membrane potential after the last step's reset."""
    refractory_left: np.ndarray
    """[B, n] steps the neuron is still held at V_r."""
    steps_since_release: np.ndarray
    """[B, n] steps since each neuron's last release (saturating)."""
    released: np.ndarray
    """[B, n] whether each neuron released vesicles at the last step."""

    @classmethod
    def at_rest(cls, batch_size: int, n_neurons: int, params: NeuronParams) -> SimulatorState:
        """Every neuron at V_r with no history (t_r = -inf)."""
        state = cls(
            voltage_mV=np.empty((batch_size, n_neurons), dtype=np.float64),
            refractory_left=np.empty((batch_size, n_neurons), dtype=np.int32),
            steps_since_release=np.empty((batch_size, n_neurons), dtype=np.int32),
            released=np.empty((batch_size, n_neurons), dtype=np.bool_),
        )
        state.reset(np.ones(batch_size, dtype=bool), params)
        return state

    def reset(self, which: np.ndarray, params: NeuronParams) -> None:
        """Put the networks selected by the [B] mask ``which`` back at rest."""
        self.voltage_mV[which] = params.v_rest_mV
        self.refractory_left[which] = 0
        self.steps_since_release[which] = _SINCE_RELEASE_CAP
        self.released[which] = False

    def copy(self) -> SimulatorState:
        return SimulatorState(
            self.voltage_mV.copy(),
            self.refractory_left.copy(),
            self.steps_since_release.copy(),
            self.released.copy(),
        )


def advance(
    state: SimulatorState,
    weights: np.ndarray,
    actions: np.ndarray,
    params: NeuronParams,
    out_voltage: np.ndarray,
    out_spikes: np.ndarray,
) -> None:
    """Advance ``state`` in place by ``actions.shape[1]`` steps, with no input checks.

    ``weights`` is int8 [B or 1, n, n], ``actions`` int64 [B, T], ``out_voltage``
    float64 and ``out_spikes`` bool [B, T, n], all C-contiguous. This is the hot path
    of the environments; :func:`simulate` is the checked entry point.
    """
    tau_m = params.membrane_time_constant_ms
    kernel = _advance_parallel if actions.shape[0] >= PARALLEL_MIN_BATCH else _advance_serial
    kernel(
        weights,
        actions,
        state.voltage_mV,
        state.refractory_left,
        state.steps_since_release,
        state.released,
        params.v_rest_mV,
        params.v_threshold_mV - params.threshold_tolerance_mV,
        params.dt_ms / tau_m,
        params.dt_ms * params.stimulus_current_pA / params.capacitance_pF,
        params.dt_ms * params.synaptic_current_pA / params.capacitance_pF,
        int(params.refractory_steps),
        params.min_release_interval_steps,
        out_voltage,
        out_spikes,
    )


def as_weight_batch(weights: np.ndarray | list) -> np.ndarray:
    """Validate a connectivity matrix [n, n] or a batch [B, n, n]; return int8 [B, n, n].

    ``G[i, j]`` is the sign of the connection from presynaptic i to postsynaptic j:
    +1 excitatory, -1 inhibitory, 0 none; the diagonal must be zero.
    """
    array = np.asarray(weights)
    if array.ndim == 2:
        array = array[None]
    if array.ndim != 3 or array.shape[1] != array.shape[2]:
        raise ValueError(
            f"weights must have shape [n, n] or [batch, n, n], got {np.shape(weights)}"
        )
    if array.shape[1] < 1:
        raise ValueError("weights must describe at least one neuron")
    if not (np.issubdtype(array.dtype, np.number) or array.dtype == np.bool_):
        raise TypeError(f"weights must be numeric, got dtype {array.dtype}")
    if not np.all(np.isin(array, (-1, 0, 1))):
        raise ValueError("weights must contain only -1 (inhibitory), 0 (none) and +1 (excitatory)")
    if np.any(np.diagonal(array, axis1=1, axis2=2) != 0):
        raise ValueError("weights must have a zero diagonal: a neuron has no self-connection")
    return np.ascontiguousarray(array, dtype=np.int8)


def simulate(
    weights: np.ndarray,
    actions: np.ndarray,
    params: NeuronParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate batches of networks from rest under given action sequences.

    Args:
        weights: connectivity [n, n] (shared by the batch) or [B, n, n], values in
            {-1, 0, +1}, row = presynaptic, column = postsynaptic.
        actions: [T] or [B, T] integers in -1..n-1; -1 stimulates nobody, j
            stimulates neuron j for one step.
        params: model parameters; the paper's (Table 1) when None.

    Returns:
        ``(voltages, spikes)``: membrane potentials in mV [B, T, n] as observed
        (after integration, before reset) and spikes [B, T, n] bool. A 1-D
        ``actions`` with 2-D ``weights`` gives [T, n] arrays instead.
    """
    params = NeuronParams() if params is None else params
    if not isinstance(params, NeuronParams):
        raise TypeError(f"params must be a NeuronParams, got {type(params).__name__}")
    single = np.ndim(weights) == 2 and np.ndim(actions) == 1
    weight_batch = as_weight_batch(weights)  # [W, n, n]
    n = weight_batch.shape[1]
    action_array = np.asarray(actions)
    if action_array.ndim == 1:
        action_array = action_array[None]
    if action_array.ndim != 2:
        raise ValueError(f"actions must have shape [T] or [batch, T], got {np.shape(actions)}")
    if action_array.size and not np.issubdtype(action_array.dtype, np.integer):
        raise TypeError(f"actions must be integers, got dtype {action_array.dtype}")
    if action_array.size and (action_array.min() < DO_NOTHING or action_array.max() >= n):
        raise ValueError(f"actions must lie in -1..{n - 1} for {n} neurons")
    batch = action_array.shape[0]
    if weight_batch.shape[0] not in (1, batch):
        raise ValueError(
            f"weights batch ({weight_batch.shape[0]}) does not match actions batch ({batch})"
        )
    horizon = action_array.shape[1]
    action_array = np.ascontiguousarray(action_array, dtype=np.int64)
    voltages = np.empty((batch, horizon, n), dtype=np.float64)
    spikes = np.empty((batch, horizon, n), dtype=np.bool_)
    state = SimulatorState.at_rest(batch, n, params)
    advance(state, weight_batch, action_array, params, voltages, spikes)
    if single:
        return voltages[0], spikes[0]
    return voltages, spikes
