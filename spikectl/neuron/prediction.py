"""One step of the model predicted in NumPy, without advancing anything (docs/model.md).

What a planner asks ("does the target spike next step?") is answered here, through
the kernel's own Euler step :func:`spikectl.neuron.kernel.integrate`, so the answer
equals the simulator's to the last bit; tests/test_simulator.py holds ``one_step``
equal to ``advance``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from spikectl.neuron.kernel import integrate
from spikectl.neuron.params import NeuronParams

if TYPE_CHECKING:
    from spikectl.neuron.simulator import SimulatorState


def one_step(
    state: SimulatorState,
    weights: np.ndarray,
    actions: np.ndarray | int,
    params: NeuronParams,
    neurons: np.ndarray | None = None,
    input_mV: np.ndarray | None = None,
    neuron: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The potentials and spikes the next step of ``state`` gives; ``state`` is not changed.

    Args:
        state: B simulator states.
        weights: [1 or B, n, n] int8 signs or float64 signed strengths in units of w_in.
        actions: [B] or one simulator action for all (-1: do nothing).
        params: the neuron parameters.
        neurons: per-neuron kernel parameters [1 or B, 2, n], or None (the paper's).
        input_mV: [B, n] extra input of the step, or None.
        neuron: predict this neuron alone (arrays [B]); None: all of them ([B, n]).

    Returns:
        ``(voltage, spiked)`` as :func:`spikectl.neuron.simulator.advance` writes them
        for the step: the potential after integration and before reset (V_r for a
        refractory neuron), and whether it spiked.
    """
    n = state.voltage_mV.shape[1]
    columns = np.arange(n) if neuron is None else np.array([neuron])  # [m]
    weights = np.asarray(weights)[:, :, columns]  # [1 or B, n, m]
    # Presynaptic neurons are summed in ascending order from 0, as the kernel sums them,
    # so that float weights (scaled synapses, hypotheses) round the same way.
    synaptic_input = 0.0
    for i in range(n):
        synaptic_input = synaptic_input + np.where(
            state.released[:, i, None], weights[:, i], 0.0
        )  # [B, m]
    drive = params.synaptic_step_mV * synaptic_input
    stimulated = np.asarray(actions).reshape(-1, 1) == columns  # [B or 1, m]
    drive = np.where(stimulated, drive + params.stimulus_step_mV, drive)
    if input_mV is not None:
        drive = drive + np.asarray(input_mV)[:, columns]
    if neurons is None:
        v_spike, leak = params.v_spike_mV, params.leak_per_step
    else:
        v_spike, leak = neurons[:, 0, columns], neurons[:, 1, columns]
    voltage = integrate(state.voltage_mV[:, columns], params.v_rest_mV, leak, drive)
    refractory = state.refractory_left[:, columns] > 0
    spiked = ~refractory & (voltage >= v_spike)
    voltage = np.where(refractory, params.v_rest_mV, voltage)
    if neuron is None:
        return voltage, spiked
    return voltage[:, 0], spiked[:, 0]
