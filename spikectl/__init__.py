"""spikectl: closed-loop control of simulated neuronal networks with reinforcement learning.

The public API is re-exported here; importing the package registers the Gymnasium
environment ids (a cheap dictionary entry) and does no other work. It first checks the
environment variables Numba reads (``spikectl.environment_variables``): one it cannot use raises
:class:`~spikectl.environment_variables.EnvironmentVariableError` (a ValueError) naming it.
``load_controller`` (which needs PyTorch) loads its module on first use, and so do
``register_controller`` and the suite's ``register_task`` / ``register_suite_version``.

The extension points, one registry line each: ``register_controller`` (a controller
for ``load_controller`` and ``spikectl benchmark`` / ``realtime``), ``register_task``
(a task of a suite version; ``register_suite_version`` for a version beside v1) and
``register_env_variant`` (a ``gymnasium.make``-able variant and its flat twin).
"""

from typing import Any

from spikectl.environment_variables import EnvironmentVariableError, check_environment, import_numba

# Before Numba reads the environment: a value it cannot use is one EnvironmentVariableError
# (a ValueError) naming the variable, not a traceback from inside Numba.
check_environment()
import_numba()

from spikectl.contexts import Context, ContextSet, make_context, make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.registration import register_env_variant, register_envs
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
    "register_controller",
    "register_env_variant",
    "register_suite_version",
    "register_task",
    "sb3_compatible",
    "sb3_vec_env",
    "simulate",
    "__version__",
]


_LAZY = {
    "load_controller": "spikectl.training.loaders",
    "register_controller": "spikectl.training.loaders",
    "register_suite_version": "spikectl.experiments.suite",
    "register_task": "spikectl.experiments.suite",
}
"""Public names whose modules load on first use (the controllers import the planners)."""


def __getattr__(name: str) -> Any:
    # PEP 562: these modules import the planning and training stacks, so only on first use.
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'spikectl' has no attribute {name!r}")
