"""The one implementation of the step (docs/model.md): a Numba kernel over a batch of networks.

``_advance_kernel`` moves a batch of independent networks forward by any number of
1 ms steps and writes what an observer sees; it is compiled twice from the same source
(serially and with threads over the batch). The extensions (heterogeneous neurons,
stochastic release, extra input) are optional arguments of the same kernel: None
prunes their branches at compile time, so the paper's model does the paper's
arithmetic and nothing more. ``spikectl.neuron.simulator`` is the interface
(``advance``, ``simulate``); with ``NUMBA_DISABLE_JIT=1`` the same code runs as plain
Python.
"""

from __future__ import annotations

import numba
import numpy as np

from spikectl.neuron.params import NeuronParams

# A call is split over threads only when it has at least this many networks and this
# much work (networks x steps x neurons). Below, thread start-up costs more than it
# saves; and a one-step call of a vector environment that uses threads stalls for
# milliseconds whenever another process holds a core (measured: 4-7 ms instead of
# ~0.2 ms for 4096 networks of 8 neurons), so such calls stay serial.
PARALLEL_MIN_BATCH = 256
PARALLEL_MIN_WORK = 2**18

# steps_since_release saturates here, far beyond any release interval but below
# NEVER_RELEASES, so "no release yet" (t_r = -inf) stays ready to release.
SINCE_RELEASE_CAP = 2**30

# The kernel's ``constants`` array holds these NeuronParams quantities, slot k the k-th
# name; the kernel reads each slot through the index of the same name (Numba folds a
# global int into the code, so naming costs nothing).
CONSTANTS = (
    "v_rest_mV",
    "v_spike_mV",
    "leak_per_step",
    "stimulus_step_mV",
    "synaptic_step_mV",
    "refractory_steps",
    "min_release_interval_steps",
    "release_scale",
    "recovery_per_step",
)
(
    V_REST_MV,
    V_SPIKE_MV,
    LEAK_PER_STEP,
    STIMULUS_STEP_MV,
    SYNAPTIC_STEP_MV,
    REFRACTORY_STEPS,
    MIN_RELEASE_INTERVAL_STEPS,
    RELEASE_SCALE,
    RECOVERY_PER_STEP,
) = range(len(CONSTANTS))


def integrate(v, v_rest, leak, drive):
    """V + dt (-(V - V_r) / (R C) + I / C): the potential after one Euler step, in mV.

    ``leak`` is dt / (R C), ``drive`` dt * I / C in mV (stimulus, synaptic and extra
    input together); scalars or NumPy arrays. The kernel compiles this very function
    (it lives here so that Numba's cache, keyed on this file, sees every edit), and
    :func:`spikectl.neuron.prediction.one_step` calls it on arrays: the order of the
    operations is the model's rounding, and a prediction equals the simulator only
    while both use it.
    """
    return v + (-(v - v_rest) * leak + drive)


_integrate = numba.njit(inline="always")(integrate)


def _step_neuron(
    j, v_j, refractory_j, since_j, synaptic_j, action, model, threshold_j, leak_j,
    stochastic, may_release_j, input_j,
):  # fmt: skip
    """Neuron ``j``'s part of :func:`step_network`, from its state (``v_j``,
    ``refractory_j``, ``since_j``) and its summed synaptic input ``synaptic_j``: returns
    its new state ``(v, refractory_left, steps_since_release, released)`` and what is
    observed ``(potential before reset, spiked)``. No other neuron enters: the action
    only through ``action == j``, the others only through ``synaptic_j``.

    ``threshold_j``, ``leak_j``: its threshold (V_th less the tolerance) and dt / RC;
    ``stochastic``: whether release is stochastic, and then ``may_release_j`` whether a
    spike may release now; ``input_j``: extra input in mV, or None. (Scalars in, scalars
    out: arrays passed per neuron cost reference counting that made the kernel 5x slower.)
    """
    v_rest, _, _, stimulus_step_mV, synaptic_step_mV = model[:5]
    refractory_steps, min_release_interval = model[5:]
    since = since_j
    if since < SINCE_RELEASE_CAP:
        since += 1
    if refractory_j > 0:  # held at V_r: no integration, no spike
        return v_rest, refractory_j - 1, since, False, v_rest, False
    drive = synaptic_step_mV * synaptic_j
    if action == j:
        drive += stimulus_step_mV
    if input_j is not None:
        drive += input_j
    v_out = _integrate(v_j, v_rest, leak_j, drive)
    if v_out < threshold_j:
        return v_out, 0, since, False, v_out, False
    release = False
    if not stochastic:
        if since >= min_release_interval:
            release = True
            since = 0
    elif may_release_j:
        release = True
        since = 0
    return v_rest, refractory_steps, since, release, v_out, True


step_neuron = numba.njit(inline="always", cache=True, nogil=True)(_step_neuron)


def _step_network(
    w,  # [n, n] int8 or float64: the network's signed weights
    action,  # int: the neuron stimulated, -1 = do nothing
    v,  # [n] float64, state, updated in place
    refractory_left,  # [n] int32, state
    steps_since_release,  # [n] int32, state
    released,  # [n] bool, state: released at the previous step
    synaptic_input,  # [n] float64 scratch
    model,  # the constants of the step, from step_constants(constants)
    out_voltage,  # [B, T, n] float64: [b, t] gets the potential before reset
    out_spikes,  # [B, T, n] bool: [b, t] gets the spikes
    b,  # int: the network's row of out_voltage, out_spikes and input_mV
    t,  # int: the step's column of out_voltage, out_spikes and input_mV
    threshold,  # [n] per-neuron V_th less the tolerance, or None (the paper's)
    leak,  # [n] per-neuron dt / RC, or None
    may_release,  # [n] bool: whether a spike may release now (stochastic release), or None
    input_mV,  # [B, T, n] extra input (background activity) in mV, or None
):
    """One 1 ms step of one network, in place: the model's whole step (docs/model.md).

    ``_advance_kernel`` calls it for every network and step; the planners
    (``spikectl.planning.beam``) call it from their own compiled search on their own
    buffers, so they predict with this very arithmetic. A None input prunes its branch
    at compile time. (The constants come unpacked, once per call of the kernel:
    unpacked at every step they cost 40 % of a step of 8 neurons.)
    """
    n = v.shape[0]
    synaptic_input[:] = 0.0
    for i in range(n):
        if released[i]:
            for j in range(n):
                synaptic_input[j] += w[i, j]
    for j in range(n):
        # The paper's threshold and leak are model constants: the same arithmetic.
        if threshold is None:
            threshold_j, leak_j = model[1], model[2]
        else:
            threshold_j, leak_j = threshold[j], leak[j]
        if may_release is None:
            stochastic, may_release_j = False, False
        else:
            stochastic, may_release_j = True, may_release[j]
        if input_mV is None:
            (v[j], refractory_left[j], steps_since_release[j], released[j],
             out_voltage[b, t, j], out_spikes[b, t, j]) = step_neuron(
                j, v[j], refractory_left[j], steps_since_release[j], synaptic_input[j], action,
                model, threshold_j, leak_j, stochastic, may_release_j, None,
            )  # fmt: skip
        else:
            (v[j], refractory_left[j], steps_since_release[j], released[j],
             out_voltage[b, t, j], out_spikes[b, t, j]) = step_neuron(
                j, v[j], refractory_left[j], steps_since_release[j], synaptic_input[j], action,
                model, threshold_j, leak_j, stochastic, may_release_j, input_mV[b, t, j],
            )  # fmt: skip


step_network = numba.njit(inline="always", cache=True, nogil=True)(_step_network)


def _predict_neuron(w, action, v, refractory_left, released, model, j, threshold, leak):
    """(potential before reset, spiked) of neuron ``j`` at the next step of one network,
    which is not changed: what :func:`step_network` would write for it (its synaptic
    input summed over the released neurons in the same ascending order), at the cost of
    one neuron. The planners ask it whether the target spikes next step."""
    synaptic_j = 0.0
    for i in range(v.shape[0]):
        if released[i]:
            synaptic_j += w[i, j]
    if threshold is None:
        threshold_j, leak_j = model[1], model[2]
    else:
        threshold_j, leak_j = threshold[j], leak[j]
    return step_neuron(j, v[j], refractory_left[j], 0, synaptic_j, action, model, threshold_j,
                       leak_j, False, False, None)[4:]  # fmt: skip


predict_neuron = numba.njit(inline="always", cache=True, nogil=True)(_predict_neuron)


def _step_constants(constants):
    """What :func:`step_network` takes as ``model``, from the kernel's ``constants``."""
    return (
        constants[V_REST_MV], constants[V_SPIKE_MV], constants[LEAK_PER_STEP],
        constants[STIMULUS_STEP_MV], constants[SYNAPTIC_STEP_MV],
        int(constants[REFRACTORY_STEPS]), int(constants[MIN_RELEASE_INTERVAL_STEPS]),
    )  # fmt: skip


step_constants = numba.njit(inline="always", cache=True, nogil=True)(_step_constants)


def _advance_kernel(
    weights,  # [W, n, n] int8, or float64 with scaled synapses; W == 1 (shared) or W == B
    actions,  # [B, T] int64, -1 = do nothing
    voltage,  # [B, n] float64, state, updated in place
    refractory_left,  # [B, n] int32, state
    steps_since_release,  # [B, n] int32, state
    released,  # [B, n] bool, state: released at the previous step
    constants,  # [9] float64, the NeuronParams quantities named in CONSTANTS
    out_voltage,  # [B, T, n] float64
    out_spikes,  # [B, T, n] bool
    # The extensions, each None in the paper's model. Numba compiles one
    # specialisation per combination of present inputs and prunes the branches of the
    # absent ones, so the paper's path does the paper's arithmetic and nothing more.
    neurons,  # [P, 2, n] per-neuron (v_spike, leak_per_step), P == 1 (shared) or P == B
    release_uniforms,  # [B, T, n] uniforms in [0, 1): stochastic release
    input_mV,  # [B, T, n] extra input (background activity) in mV
):
    model = step_constants(constants)
    release_scale = constants[RELEASE_SCALE]
    recovery_per_step = constants[RECOVERY_PER_STEP]
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
        if neurons is None:
            threshold_b = None
            leak_b = None
        elif neurons.shape[0] == 1:
            threshold_b = neurons[0, 0].copy()
            leak_b = neurons[0, 1].copy()
        else:
            threshold_b = neurons[b, 0].copy()
            leak_b = neurons[b, 1].copy()
        if release_uniforms is None:
            may_release = None
        else:
            may_release = np.empty(n, dtype=np.bool_)
        for t in range(horizon):
            if release_uniforms is not None:
                # A spike at t releases with probability p_r * (1 - exp(-(t - t_r) / tau_R))
                # (t_r = -inf: p_r), decided before the step so that it stays free of calls.
                for j in range(n):
                    since = min(since_b[j] + 1, SINCE_RELEASE_CAP)
                    probability = release_scale * (1.0 - np.exp(-since * recovery_per_step))
                    may_release[j] = release_uniforms[b, t, j] < probability
            step_network(w, actions[b, t], v_b, refractory_b, since_b, released_b,
                         synaptic_input, model, out_voltage, out_spikes, b, t,
                         threshold_b, leak_b, may_release, input_mV)  # fmt: skip
        voltage[b] = v_b
        refractory_left[b] = refractory_b
        steps_since_release[b] = since_b
        released[b] = released_b


# One kernel, compiled twice: serially for small batches (the single environment)
# and with threads over the batch for large ones. Both give identical results.
# The parallel build is not cached: loaded from Numba's cache it ran at half speed
# (numba 0.68, measured with benchmarks/bench_simulator.py).
advance_serial = numba.njit(cache=True, nogil=True)(_advance_kernel)
advance_parallel = numba.njit(nogil=True, parallel=True)(_advance_kernel)


# The constants of the kernel, per NeuronParams object: computing them costs more than
# a whole single-network step, so they are kept (with a reference to their params, so
# that an id is never reused while its entry exists).
_CONSTANTS: dict[int, tuple[NeuronParams, np.ndarray]] = {}


def kernel_constants(params: NeuronParams) -> np.ndarray:
    """The kernel's ``constants`` for ``params`` (computed once per params object)."""
    entry = _CONSTANTS.get(id(params))
    if entry is None or entry[0] is not params:
        constants = np.array([getattr(params, name) for name in CONSTANTS], dtype=np.float64)
        if len(_CONSTANTS) >= 1024:
            _CONSTANTS.clear()
        entry = _CONSTANTS[id(params)] = (params, constants)
    return entry[1]
