"""The building blocks of the four networks, under the one name they had before they
were split by concept (docs/agents.md); code that imports them from here keeps working.

- :mod:`spikectl.agents.observation`: the observation contract, its checks, conversion
- :mod:`spikectl.agents.features`: featurisation of observations into network inputs
- :mod:`spikectl.agents.encoders`: MLP, context encoder, per-neuron LSTM, neuron mixer
- :mod:`spikectl.agents.heads`: Q heads, the auxiliary predictor, masking and acting
"""

from spikectl.agents.encoders import MLP, ContextEncoder, NeuronMixer, PerNeuronLSTM
from spikectl.agents.features import (
    action_one_hot,
    neuron_indicator,
    normalised_voltage,
    per_neuron_features,
    shift_pattern,
    system_features,
)
from spikectl.agents.heads import NextVoltagePredictor, PerNeuronQHead, greedy_action, masked_q
from spikectl.agents.observation import (
    OBS_KEYS,
    check_observation,
    check_state,
    long_indices,
    observation_batch,
)

__all__ = [
    "MLP",
    "OBS_KEYS",
    "ContextEncoder",
    "NeuronMixer",
    "NextVoltagePredictor",
    "PerNeuronLSTM",
    "PerNeuronQHead",
    "action_one_hot",
    "check_observation",
    "check_state",
    "greedy_action",
    "long_indices",
    "masked_q",
    "neuron_indicator",
    "normalised_voltage",
    "observation_batch",
    "per_neuron_features",
    "shift_pattern",
    "system_features",
]
