"""The registered environment variants, as settings of the trainer's environment config.

A variant (``spikectl/NeuronControlNoisy-v0``, ...; ``spikectl.envs.registration.VARIANTS``)
is the base environment plus keyword arguments. Here they are read as *settings*: field
paths within ``EnvConfig`` (``"n_neurons"``, ``"params.capacitance_pF"``,
``"extensions.observation_noise_mV"``) with the values the variant gives them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams

SIZE_FIELDS = ("n_neurons", "episode_length")
TAKEN_KWARGS = (*SIZE_FIELDS, "params", "extensions")
"""Keyword arguments of a registered variant that the trainer's environment takes over."""


def variant_kwargs(env_id: str) -> dict[str, Any]:
    """The keyword arguments a registered spikectl environment id is made with; a clear
    error for an unknown id, another library's environment or arguments the trainer
    cannot take over."""
    import gymnasium

    from spikectl.envs.registration import register_envs

    register_envs()

    if not isinstance(env_id, str) or env_id not in gymnasium.registry:
        ours = sorted(name for name in gymnasium.registry if name.startswith("spikectl/"))
        raise ValueError(f"env: unknown environment id {env_id!r}; registered: {', '.join(ours)}")
    spec = gymnasium.spec(env_id)
    if not str(spec.entry_point).startswith("spikectl."):
        raise ValueError(f"env: {env_id!r} is not a spikectl environment ({spec.entry_point})")
    kwargs = dict(spec.kwargs)
    unknown = sorted(set(kwargs) - set(TAKEN_KWARGS))
    if unknown:
        raise ValueError(f"env: {env_id!r} sets {unknown}, which the trainer does not take over")
    return kwargs


def variant_settings(env_id: str) -> dict[str, Any]:
    """The settings ``env_id`` changes from the base environment, by field path."""
    kwargs = variant_kwargs(env_id)
    settings = {name: kwargs[name] for name in SIZE_FIELDS if name in kwargs}
    for prefix in ("params", "extensions"):
        settings.update({f"{prefix}.{k}": v for k, v in _as_dict(kwargs.get(prefix)).items()})
    return settings


def flat_settings(
    sizes: Mapping[str, int], params: NeuronParams, extensions: Extensions
) -> dict[str, Any]:
    """Every setting a variant may change, by field path (the inverse of
    :func:`split_settings`)."""
    return {
        **{name: sizes[name] for name in SIZE_FIELDS},
        **{f"params.{k}": v for k, v in params.to_dict().items()},
        **{f"extensions.{k}": v for k, v in extensions.to_dict().items()},
    }


def split_settings(settings: Mapping[str, Any]) -> dict[str, Any]:
    """Field paths back to EnvConfig arguments: the sizes, ``params`` and ``extensions``."""
    parts: dict[str, dict[str, Any]] = {"params": {}, "extensions": {}}
    sizes = {}
    for name, value in settings.items():
        prefix, _, field = name.partition(".")
        if field:
            parts[prefix][field] = value
        else:
            sizes[name] = value
    return {
        **sizes,
        "params": NeuronParams.from_dict(parts["params"]),
        "extensions": Extensions.from_dict(parts["extensions"]),
    }


def _as_dict(value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if isinstance(value, (NeuronParams, Extensions)):
        return value.to_dict()
    return dict(value)
