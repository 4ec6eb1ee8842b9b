"""The environment in the conventions of generic RL libraries (docs/ecosystem.md).

``conventions`` holds them in one place (zero-based actions, int8 masks, flat float32
observations, the illegal-action rule); ``flat_env`` and ``flat_vector_env`` are the
environments of the registered flat ids (``spikectl/NeuronControlFlat-v0``, ...);
``final_info`` puts episode statistics where scripts written for Gymnasium < 1.0 read
them (the ``...FlatFinalInfo-v0`` ids); ``flat_policy`` plays a policy trained on a flat
id as a controller (the suite, ``evaluate_policy``, the real-time rig); ``sb3`` puts any
single environment behind the same conventions for Stable-Baselines3, and
``sb3_vec_adapter`` the batched one behind SB3's ``VecEnv`` (imported only when used: it
needs SB3).
"""

from spikectl.envs.registration import final_info_id
from spikectl.wrappers.conventions import (
    DO_NOTHING,
    ILLEGAL_ACTIONS,
    MASK_DTYPE,
    FlatObservation,
    SB3Observation,
    from_env_action,
    observation_for,
    to_env_action,
    voltage_bounds_mV,
)
from spikectl.wrappers.final_info import FinalInfo, FinalInfoEpisodeStatistics
from spikectl.wrappers.flat_env import FlatEnv, FlatNeuronControlEnv
from spikectl.wrappers.flat_policy import FlatPolicy, FlatPolicyController, FlatPolicyError
from spikectl.wrappers.flat_vector_env import FlatNeuronControlVectorEnv
from spikectl.wrappers.sb3 import (
    SB3CompatibleEnv,
    make_sb3_compatible,
    sb3_compatible,
    sb3_vec_env,
)

__all__ = [
    "DO_NOTHING",
    "ILLEGAL_ACTIONS",
    "MASK_DTYPE",
    "FinalInfo",
    "FinalInfoEpisodeStatistics",
    "FlatEnv",
    "FlatNeuronControlEnv",
    "FlatNeuronControlVectorEnv",
    "FlatPolicy",
    "FlatPolicyController",
    "FlatPolicyError",
    "FlatObservation",
    "SB3CompatibleEnv",
    "SB3Observation",
    "final_info_id",
    "from_env_action",
    "make_sb3_compatible",
    "observation_for",
    "sb3_compatible",
    "sb3_vec_env",
    "to_env_action",
    "voltage_bounds_mV",
]
