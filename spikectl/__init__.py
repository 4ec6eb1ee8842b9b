"""spikectl: closed-loop control of simulated neuronal networks with reinforcement learning.

The public API is re-exported here; importing the package registers the Gymnasium
environment ids (a cheap dictionary entry) and does no other work. It first checks the
environment variables Numba reads (``spikectl.environment_variables``): one it cannot use raises
:class:`~spikectl.environment_variables.EnvironmentVariableError` (a ValueError) naming it.
``load_controller`` (which needs PyTorch) loads its module on first use.
"""

from typing import Any

from spikectl.environment_variables import EnvironmentVariableError, check_environment, import_numba

# Before Numba reads the environment: a value it cannot use is one EnvironmentVariableError
# (a ValueError) naming the variable, not a traceback from inside Numba.
check_environment()
import_numba()

from spikectl.contexts import Context, ContextSet, make_context, make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.registration import register_envs
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import simulate
from spikectl.planning import IdentifyAndPlan, plan_episode
from spikectl.version import __version__
from spikectl.wrappers import sb3_compatible, sb3_vec_env

register_envs()

__all__ = [
    "Context",
    "ContextSet",
    "EnvironmentVariableError",
    "Extensions",
    "NeuronControlEnv",
    "NeuronControlVectorEnv",
    "IdentifyAndPlan",
    "load_controller",
    "NeuronParams",
    "make_context",
    "make_splits",
    "plan_episode",
    "sb3_compatible",
    "sb3_vec_env",
    "simulate",
    "__version__",
]


def __getattr__(name: str) -> Any:
    # PEP 562: ``spikectl.load_controller`` imports PyTorch, so only on first use.
    if name == "load_controller":
        from spikectl.training.controllers import load_controller

        globals()[name] = load_controller
        return load_controller
    raise AttributeError(f"module 'spikectl' has no attribute {name!r}")
