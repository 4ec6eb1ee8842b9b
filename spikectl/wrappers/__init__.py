"""The environment in the conventions of Stable-Baselines3 and sb3-contrib.

``sb3`` holds the single-environment wrapper, ``sb3_vec_adapter`` the adapter from the
batched environment to SB3's ``VecEnv`` (imported only when used: it needs SB3), and
``sb3_spaces`` the spaces and observations both write.
"""

from spikectl.wrappers.sb3 import (
    SB3CompatibleEnv,
    make_sb3_compatible,
    sb3_compatible,
    sb3_vec_env,
)
from spikectl.wrappers.sb3_spaces import (
    DO_NOTHING,
    ILLEGAL_ACTIONS,
    SB3Observation,
    from_env_action,
    observation_for,
    to_env_action,
    voltage_bounds_mV,
)

__all__ = [
    "DO_NOTHING",
    "ILLEGAL_ACTIONS",
    "SB3CompatibleEnv",
    "SB3Observation",
    "from_env_action",
    "make_sb3_compatible",
    "observation_for",
    "sb3_compatible",
    "sb3_vec_env",
    "to_env_action",
    "voltage_bounds_mV",
]
