"""The environment for Stable-Baselines3 and sb3-contrib: a thin layer over the flat conventions.

The registered flat ids (``spikectl/NeuronControlFlat-v0``, docs/ecosystem.md) already
speak SB3's conventions; these functions put an environment built otherwise (a paper id,
a ``NeuronControlEnv`` with a custom context set) behind the same conventions
(:mod:`spikectl.wrappers.conventions`). The paper environments keep the paper's
conventions (docs/environment.md): actions -1..n-1 with -1 = do nothing, an illegal
action raises, the voltage is unbounded and the observation is a ``Dict`` with a
``Discrete(start=-1)`` entry. :func:`sb3_compatible` wraps one environment and
:func:`sb3_vec_env` the batched one for them; neither changes the dynamics or the
rewards, only how actions and observations are written (docs/ecosystem.md).

Actions: ``Discrete(k + 1)``; 0 does nothing and a >= 1 stimulates (observable) neuron
a - 1, so action a is the base environment's a - 1 and ``action_masks()[a]`` is the
base ``info["action_mask"][a]`` unchanged. An illegal action (the target neuron)
does nothing by default (``illegal_action="do_nothing"``; ``info["illegal_action"]``
says so) or raises (``"raise"``, the base environment's behaviour).

Observations: the base ``Dict`` with ``last_action`` zero-based and the voltage clipped
to the finite bounds of :func:`voltage_bounds_mV` (``flatten=False``), or by default one
float32 vector (``flatten=True``, layout in :class:`FlatObservation`) that every SB3
policy, ``VecNormalize`` and ``VecFrameStack`` accept.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

from spikectl.config_errors import MissingExtraError
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers.flat_env import FlatEnv

if TYPE_CHECKING:
    from spikectl.wrappers.sb3_vec_adapter import SB3VecEnv


class SB3CompatibleEnv(FlatEnv):
    """:class:`~spikectl.wrappers.flat_env.FlatEnv` whose ``spec`` rebuilds it.

    See the module docstring and docs/ecosystem.md. ``gymnasium.make(env.spec)`` gives
    the same wrapped environment again (SB3's ``make_vec_env`` and evaluation helpers
    rebuild environments that way).
    """

    def __init__(
        self, env: gym.Env, *, flatten: bool = True, illegal_action: str = "do_nothing"
    ) -> None:
        super().__init__(env, flatten=flatten, illegal_action=illegal_action)
        if env.spec is not None:  # gymnasium.make(self.spec) rebuilds this environment
            self.spec = EnvSpec(
                env.spec.id,
                entry_point=make_sb3_compatible,
                nondeterministic=env.spec.nondeterministic,
                kwargs={
                    **env.spec.kwargs,
                    "env_id": env.spec.id,
                    "flatten": flatten,
                    "illegal_action": illegal_action,
                },
            )


def sb3_compatible(
    env: gym.Env, *, flatten: bool = True, illegal_action: str = "do_nothing"
) -> SB3CompatibleEnv:
    """``env`` (a ``NeuronControlEnv`` or ``gymnasium.make`` of a spikectl id) wrapped for
    Stable-Baselines3 and sb3-contrib: see :class:`SB3CompatibleEnv` and docs/ecosystem.md.

    ``flatten``: one float32 vector (default) or a ``Dict`` (for ``MultiInputPolicy``).
    ``illegal_action``: ``"do_nothing"`` (default) or ``"raise"``.
    """
    return SB3CompatibleEnv(env, flatten=flatten, illegal_action=illegal_action)


def make_sb3_compatible(
    env_id: str, *, flatten: bool = True, illegal_action: str = "do_nothing", **kwargs: Any
) -> SB3CompatibleEnv:
    """``sb3_compatible(gymnasium.make(env_id, **kwargs), ...)``: the entry point of the
    wrapped environment's ``spec``."""
    return sb3_compatible(
        gym.make(env_id, **kwargs), flatten=flatten, illegal_action=illegal_action
    )


def sb3_vec_env(
    env: NeuronControlVectorEnv | gym.vector.VectorEnv,
    *,
    flatten: bool = True,
    illegal_action: str = "do_nothing",
) -> SB3VecEnv:
    """The batched ``NeuronControlVectorEnv`` (or ``gymnasium.make_vec`` of a spikectl id) as
    a Stable-Baselines3 ``VecEnv``, with the spaces of :func:`sb3_compatible` and per-env
    ``action_masks`` for ``MaskablePPO``; needs ``pip install "spikectl[sb3]"``."""
    try:
        from spikectl.wrappers.sb3_vec_adapter import SB3VecEnv
    except ImportError as error:
        raise MissingExtraError(
            f"sb3_vec_env needs Stable-Baselines3 ({error}); install it with "
            'pip install "spikectl[sb3]"'
        ) from None
    return SB3VecEnv(env, flatten=flatten, illegal_action=illegal_action)


__all__ = ["SB3CompatibleEnv", "make_sb3_compatible", "sb3_compatible", "sb3_vec_env"]
