"""The environments: the single and the batched Gymnasium environment, rendering,
registration and rollouts of policies on the batched one.

Built on ``spikectl.neuron`` and ``spikectl.contexts``.
"""

from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.env_arguments import SeedError
from spikectl.envs.env_support import GeneratedContexts
from spikectl.envs.registration import ENV_ID, FLAT_ENV_ID, register_env_variant, register_envs
from spikectl.envs.vector_env import NeuronControlVectorEnv

__all__ = [
    "ENV_ID", "FLAT_ENV_ID", "GeneratedContexts", "NeuronControlEnv", "NeuronControlVectorEnv",
    "SeedError", "register_env_variant", "register_envs",
]  # fmt: skip
