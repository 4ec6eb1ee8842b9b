"""Episode statistics where scripts written for Gymnasium < 1.0 read them: ``final_info``.

Before Gymnasium 1.0, a vector environment reset a finished sub-environment inside the
step and handed that sub-environment's last info on as ``infos["final_info"][i]`` (an
object array, ``None`` for the others). Scripts written then, CleanRL's ``ppo.py`` and
``dqn.py`` as published among them, log their learning curve from there::

    if "final_info" in infos:
        for info in infos["final_info"]:
            if info and "episode" in info:
                writer.add_scalar("charts/episodic_return", info["episode"]["r"], step)

Gymnasium 1.x vector environments reset on the next step and write no ``final_info``, so
those scripts run but never log an episodic return. :class:`FinalInfoEpisodeStatistics`
puts back what they read: at an episode's end the step's info carries ``final_info``, a
:class:`FinalInfo` holding ``episode`` = ``{"r": return, "l": length}``. A
:class:`FinalInfo` is a read-only mapping and deliberately not a ``dict``: Gymnasium's
vector environments split a ``dict`` entry into one array per key, but keep any other
object whole, per sub-environment, in an object array, which is the old
``infos["final_info"]``. Everything else (observations, rewards, episode ends, the rest
of the info) is the wrapped environment's, unchanged.

The published scripts build their environments from an id alone, so
:func:`spikectl.envs.register_envs` registers a twin of every flat id (and
``register_env_variant`` of every new one) with the wrapper applied by Gymnasium
itself: ``spikectl/NeuronControlFlatFinalInfo-v0`` and so on
(``--env-id spikectl:spikectl/NeuronControlFlatFinalInfo-v0``; docs/ecosystem.md).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import gymnasium as gym

"""A flat id's twin's name adds it (``NeuronControlFlat`` -> ``NeuronControlFlatFinalInfo``)."""


class FinalInfo(Mapping[str, Any]):
    """A read-only mapping of a finished episode's entries (``episode``: ``r``, ``l``).

    A ``Mapping`` that is not a ``dict``, so that Gymnasium's vector environments keep it
    whole per sub-environment (see the module docstring); picklable, so that
    ``AsyncVectorEnv`` can send it between processes.
    """

    def __init__(self, entries: Mapping[str, Any]) -> None:
        self._entries = dict(entries)

    def __getitem__(self, key: str) -> Any:
        return self._entries[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"FinalInfo({self._entries!r})"


class FinalInfoEpisodeStatistics(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """At each episode's end, adds ``info["final_info"] = FinalInfo({"episode": {"r": R,
    "l": L}})``: R the episode's return (the sum of its rewards, a float), L its length
    in steps (an int); the other steps' infos are unchanged.

    For scripts written for Gymnasium < 1.0's vector environments (module docstring).
    Gymnasium's own ``RecordEpisodeStatistics`` may wrap it as well: it writes
    ``info["episode"]``, a key this wrapper leaves alone.
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self._return = 0.0
        self._length = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        self._return = 0.0
        self._length = 0
        return self.env.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._return += float(reward)
        self._length += 1
        if terminated or truncated:
            episode = {"r": self._return, "l": self._length}
            info = {**info, "final_info": FinalInfo({"episode": episode})}
        return observation, reward, terminated, truncated, info
