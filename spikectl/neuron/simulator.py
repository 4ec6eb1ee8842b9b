"""The batched simulator (docs/model.md): LIF neurons with short-term depression.

There is one implementation of the dynamics, the Numba kernel ``_advance_kernel`` in
``spikectl.neuron.kernel``. It moves a batch of independent networks forward by any number of
1 ms steps and writes what an observer sees. ``simulate`` runs whole action sequences
through it; ``advance`` runs one step (or a few) of a :class:`SimulatorState` and is
what the environments call. With ``NUMBA_DISABLE_JIT=1`` the same code runs as plain
Python.

Order inside step t, given action a_t (docs/model.md):

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
from typing import NamedTuple

import numba
import numpy as np

from spikectl.environment_variables import threading_layer_error
from spikectl.files import TooLargeError, check_fits_in_memory
from spikectl.neuron.kernel import (
    PARALLEL_MIN_BATCH,
    PARALLEL_MIN_WORK,
    SINCE_RELEASE_CAP,
    advance_parallel,
    advance_serial,
    kernel_constants,
)
from spikectl.neuron.params import NeuronParams

__all__ = [
    "DO_NOTHING",
    "PARALLEL_MIN_BATCH",
    "PARALLEL_MIN_WORK",
    "SimulatorState",
    "advance",
    "as_weight_batch",
    "neuron_parameters",
    "simulate",
    "uniform_neuron_parameters",
]

DO_NOTHING = -1
"""The action that stimulates no neuron."""


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
        self.steps_since_release[which] = SINCE_RELEASE_CAP
        self.released[which] = False

    def copy(self) -> SimulatorState:
        """An independent copy (every array copied)."""
        return SimulatorState(
            self.voltage_mV.copy(),
            self.refractory_left.copy(),
            self.steps_since_release.copy(),
            self.released.copy(),
        )


def neuron_parameters(
    params: NeuronParams, thresholds_mV: np.ndarray, time_constants_ms: np.ndarray
) -> np.ndarray:
    """Per-neuron kernel parameters [P, 2, n] from thresholds V_th and time constants R C.

    ``thresholds_mV`` and ``time_constants_ms`` are [P, n] (heterogeneous neurons, an
    extension); row 0 is V_th minus the tolerance, row 1 is dt / tau_m. P == 1 is
    shared by the batch, P == B gives each network its own.
    """
    thresholds, time_constants = np.broadcast_arrays(
        np.asarray(thresholds_mV, dtype=np.float64), np.asarray(time_constants_ms, dtype=np.float64)
    )
    return np.ascontiguousarray(
        np.stack(
            [thresholds - params.threshold_tolerance_mV, params.dt_ms / time_constants], axis=-2
        )
    )


def uniform_neuron_parameters(params: NeuronParams, batch: int, n_neurons: int) -> np.ndarray:
    """[batch, 2, n] kernel parameters of the paper's identical neurons."""
    return neuron_parameters(
        params,
        np.full((batch, n_neurons), params.v_threshold_mV),
        np.full((batch, n_neurons), params.membrane_time_constant_ms),
    )


class DrawnInputs(NamedTuple):
    """The random inputs the extensions draw for each step, for :func:`advance` (either
    may be None: that extension is off)."""

    release_uniforms: np.ndarray | None = None
    """float64 [B, T, n] in [0, 1): makes release stochastic (a spike releases iff
    u < p_r (1 - exp(-(t - t_r) / tau_R)))."""
    input_mV: np.ndarray | None = None
    """float64 [B, T, n]: extra input added to the drive of non-refractory neurons."""


def advance(
    state: SimulatorState,
    weights: np.ndarray,
    actions: np.ndarray,
    params: NeuronParams,
    out_voltage: np.ndarray,
    out_spikes: np.ndarray,
    neurons: np.ndarray | None = None,
    drawn: DrawnInputs | None = None,
) -> None:
    """Advance ``state`` in place by ``actions.shape[1]`` steps, with no input checks.

    ``weights`` is int8 or float64 [B or 1, n, n], ``actions`` int64 [B, T],
    ``out_voltage`` float64 and ``out_spikes`` bool [B, T, n], all C-contiguous. This
    is the hot path of the environments; :func:`simulate` is the checked entry point.

    The optional inputs are the extensions (None: the paper's model): ``neurons``
    per-neuron parameters [1 or B, 2, n] from :func:`neuron_parameters`; ``drawn`` the
    step's random inputs (:class:`DrawnInputs`).
    """
    release_uniforms, input_mV = (None, None) if drawn is None else drawn
    batch, steps = actions.shape
    work = batch * steps * weights.shape[-1]
    threaded = batch >= PARALLEL_MIN_BATCH and work >= PARALLEL_MIN_WORK
    if threaded and not _threads_started:
        _start_threads()
    kernel = advance_parallel if threaded else advance_serial
    kernel(
        weights,
        actions,
        state.voltage_mV,
        state.refractory_left,
        state.steps_since_release,
        state.released,
        kernel_constants(params),
        out_voltage,
        out_spikes,
        neurons,
        release_uniforms,
        input_mV,
    )


_threads_started = False


def _start_threads() -> None:
    """Start Numba's threads before the first threaded call: a threading layer that
    cannot load (``NUMBA_THREADING_LAYER=tbb`` without TBB) is one named error, not a
    ValueError from inside the kernel's dispatch."""
    global _threads_started
    try:
        numba.get_num_threads()  # starts the threading layer
    except ValueError as error:
        raise threading_layer_error(error) from None
    _threads_started = True


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


MAX_SIMULATE_STEPS = 10**8
"""The most steps one :func:`simulate` call runs (1000 times the longest episode a context
may have); longer runs go through :func:`advance` in pieces."""


def simulate(
    weights: np.ndarray,
    actions: np.ndarray,
    params: NeuronParams | None = None,
    *,
    thresholds_mV: np.ndarray | None = None,
    membrane_time_constants_ms: np.ndarray | None = None,
    synaptic_scale: np.ndarray | None = None,
    release_uniforms: np.ndarray | None = None,
    input_mV: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate batches of networks from rest under given action sequences.

    Args:
        weights: connectivity [n, n] (shared by the batch) or [B, n, n], values in
            {-1, 0, +1}, row = presynaptic, column = postsynaptic.
        actions: [T] or [B, T] integers in -1..n-1; -1 stimulates nobody, j
            stimulates neuron j for one step.
        params: model parameters; the paper's (Table 1) when None.

    Keyword-only extensions (docs/extensions.md), all None in the paper's model:
        thresholds_mV, membrane_time_constants_ms: per-neuron V_th and R C, [n] or
            [B, n] (heterogeneous neurons; the other one defaults to ``params``).
        synaptic_scale: [n, n] or [B, n, n] factors >= 0 on w_in per synapse.
        release_uniforms: [T, n] or [B, T, n] uniforms in [0, 1]: stochastic
            release, a spike releases iff u < p_r (1 - exp(-(t - t_r) / tau_R)).
        input_mV: [T, n] or [B, T, n] extra input (e.g. background activity) added
            to the drive of non-refractory neurons, in mV.

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
    check_fits_in_memory(
        batch * action_array.shape[1] * n * 9,  # float64 voltages and bool spikes
        f"simulating {batch:,} x {action_array.shape[1]:,} steps of {n} neurons",
        "simulate fewer steps or networks per call",
    )
    if action_array.shape[1] > MAX_SIMULATE_STEPS:
        raise TooLargeError(
            f"simulate: {action_array.shape[1]:,} steps per call is above the limit of "
            f"{MAX_SIMULATE_STEPS:,}: simulate in pieces, carrying a SimulatorState "
            "through advance()"
        )
    if weight_batch.shape[0] not in (1, batch):
        raise ValueError(
            f"weights batch ({weight_batch.shape[0]}) does not match actions batch ({batch})"
        )
    horizon = action_array.shape[1]
    action_array = np.ascontiguousarray(action_array, dtype=np.int64)
    neurons = None
    if thresholds_mV is not None or membrane_time_constants_ms is not None:
        thresholds = _per_network(thresholds_mV, (n,), batch, "thresholds_mV",
                                  params.v_threshold_mV)  # fmt: skip
        time_constants = _per_network(membrane_time_constants_ms, (n,), batch,
                                      "membrane_time_constants_ms",
                                      params.membrane_time_constant_ms)  # fmt: skip
        if (thresholds <= params.v_rest_mV).any():
            raise ValueError("thresholds_mV must lie above v_rest_mV")
        if (time_constants < params.dt_ms).any():
            raise ValueError("membrane_time_constants_ms must be >= dt_ms")
        neurons = neuron_parameters(params, thresholds, time_constants)
    if synaptic_scale is not None:
        scale = _per_network(synaptic_scale, (n, n), batch, "synaptic_scale")
        if (scale < 0).any():
            raise ValueError("synaptic_scale must be >= 0")
        weight_batch = np.ascontiguousarray(weight_batch * scale, dtype=np.float64)
        if weight_batch.shape[0] not in (1, batch):
            raise ValueError("synaptic_scale batch does not match the weights / actions batch")
    if release_uniforms is not None:
        release_uniforms = _per_network(release_uniforms, (horizon, n), batch,
                                        "release_uniforms", repeat_shared=True)  # fmt: skip
        if ((release_uniforms < 0) | (release_uniforms > 1)).any():
            raise ValueError("release_uniforms must lie in [0, 1]")
    if input_mV is not None:
        input_mV = _per_network(input_mV, (horizon, n), batch, "input_mV", repeat_shared=True)
    voltages = np.empty((batch, horizon, n), dtype=np.float64)
    spikes = np.empty((batch, horizon, n), dtype=np.bool_)
    state = SimulatorState.at_rest(batch, n, params)
    advance(state, weight_batch, action_array, params, voltages, spikes, neurons,
            DrawnInputs(release_uniforms, input_mV))  # fmt: skip
    if single:
        return voltages[0], spikes[0]
    return voltages, spikes


def _per_network(
    values: np.ndarray | None,
    shape: tuple[int, ...],
    batch: int,
    name: str,
    default=None,
    *,
    repeat_shared: bool = False,
) -> np.ndarray:
    """``values`` of one network ``shape`` or of a batch [B, *shape] as float64 [1 or B, ...].

    With ``repeat_shared`` the batch must be B and one network's values are repeated
    for each (the kernel's per-step inputs have no shared form).
    """
    if values is None:
        return np.full((1, *shape), default, dtype=np.float64)
    array = np.asarray(values, dtype=np.float64)
    rows = (batch,) if repeat_shared else (1, batch)
    if array.shape == shape:
        array = np.broadcast_to(array, (rows[0], *shape))
    if array.shape[1:] != shape or array.shape[0] not in rows:
        raise ValueError(
            f"{name} must have shape {list(shape)} or [{batch}, {', '.join(map(str, shape))}], "
            f"got {list(np.shape(values))}"
        )
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite")
    return np.ascontiguousarray(array)
