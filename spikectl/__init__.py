"""spikectl: closed-loop control of simulated neuronal networks with reinforcement learning.

The public API is re-exported here; importing the package registers the Gymnasium
environment ids (a cheap dictionary entry) and does no other work.
"""

from spikectl.contexts import Context, ContextSet, make_context, make_splits
from spikectl.env import NeuronControlEnv
from spikectl.extensions import Extensions
from spikectl.params import NeuronParams
from spikectl.planning import IdentifyAndPlan, plan_episode
from spikectl.registration import register_envs
from spikectl.simulator import simulate
from spikectl.vector_env import NeuronControlVectorEnv
from spikectl.wrappers import sb3_compatible, sb3_vec_env

register_envs()

__all__ = [
    "Context",
    "ContextSet",
    "Extensions",
    "NeuronControlEnv",
    "NeuronControlVectorEnv",
    "IdentifyAndPlan",
    "NeuronParams",
    "make_context",
    "make_splits",
    "plan_episode",
    "sb3_compatible",
    "sb3_vec_env",
    "simulate",
]
__version__ = "0.1.0"
