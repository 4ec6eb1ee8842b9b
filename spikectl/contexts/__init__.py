"""Contexts: the generated networks, targets and patterns, their sets and files.

``context`` is one context, ``generation`` draws single contexts, ``context_set`` holds
sequences of them, ``splits`` the paper's splits, ``file_format`` reads and writes their
``.npz`` files. Built on ``spikectl.neuron`` only.
"""

from spikectl.contexts.context import Context
from spikectl.contexts.context_set import ContextSet
from spikectl.contexts.file_format import ContextFileError
from spikectl.contexts.generation import (
    MAX_EPISODE_LENGTH,
    MAX_N_NEURONS,
    NeuronSetup,
    make_context,
)
from spikectl.contexts.splits import make_splits, make_validation_set

__all__ = [
    "MAX_EPISODE_LENGTH",
    "MAX_N_NEURONS",
    "Context",
    "ContextFileError",
    "ContextSet",
    "NeuronSetup",
    "make_context",
    "make_splits",
    "make_validation_set",
]
