"""The neuron model: parameters, the Numba kernel, the simulator and the extensions.

The lowest layer of spikectl: it imports nothing else from the package.
"""

from spikectl.neuron.extensions import Extensions, Heterogeneity
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance, simulate

__all__ = [
    "DO_NOTHING",
    "Extensions",
    "Heterogeneity",
    "NeuronParams",
    "SimulatorState",
    "advance",
    "simulate",
]
