"""Gymnasium registration of the environment ids: the paper's, its variants and their
flat twins.

A variant is the paper's environment with a few keyword arguments changed, registered
in :data:`VARIANTS` (one line: :func:`register_env_variant`); every variant is
registered with Gymnasium twice, as the paper's strict environment and as its flat twin
(``spikectl/NeuronControlNoisy-v0`` and ``spikectl/NeuronControlNoisyFlat-v0``).
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Mapping
from typing import Any

import gymnasium

from spikectl.registry import Registry, RegistryError

ENV_ID = "spikectl/NeuronControl-v0"

FLAT_ENV_ID = "spikectl/NeuronControlFlat-v0"
"""The paper's task in generic RL libraries' conventions (spikectl.wrappers.flat_env)."""

PAPER_ENTRY_POINTS = (
    "spikectl.envs.env:NeuronControlEnv",
    "spikectl.envs.vector_env:NeuronControlVectorEnv",
)
FLAT_ENTRY_POINTS = (
    "spikectl.wrappers.flat_env:FlatNeuronControlEnv",
    "spikectl.wrappers.flat_vector_env:FlatNeuronControlVectorEnv",
)

VARIANTS: Registry[dict[str, Any]] = Registry("variant")
"""Registered variants: id -> keyword arguments of the paper's environment (JSON-ready,
so that specs serialise), in registration order; :func:`register_envs` registers each
with Gymnasium, and :func:`register_env_variant` adds one."""

# Measurement noise on the observed potentials (docs/extensions.md).
VARIANTS.register("spikectl/NeuronControlNoisy-v0", {"extensions": {"observation_noise_mV": 2.0}})
# A quarter of the neurons (2 of 8) hidden: neither observed nor stimulable.
VARIANTS.register("spikectl/NeuronControlPartial-v0", {"extensions": {"hidden_fraction": 0.25}})
# Larger networks, the same topology rule: 16 and 32 neurons (the suite's n16 and n32).
VARIANTS.register("spikectl/NeuronControl16-v0", {"n_neurons": 16})
VARIANTS.register("spikectl/NeuronControl32-v0", {"n_neurons": 32})
# Loop latency of 1 and 2 steps: an action lands that many steps after it is chosen.
VARIANTS.register("spikectl/NeuronControlLatency1-v0", {"extensions": {"latency_steps": 1}})
VARIANTS.register("spikectl/NeuronControlLatency2-v0", {"extensions": {"latency_steps": 2}})
# Every extension at once, at moderate strength.
VARIANTS.register("spikectl/NeuronControlRealistic-v0", {
    "extensions": {
        "hidden_fraction": 0.25,
        "threshold_spread": 0.1,
        "time_constant_spread": 0.1,
        "synaptic_spread": 0.1,
        "observation_noise_mV": 2.0,
        "bleaching_time_constant_steps": 300.0,
        "stochastic_release": True,
        "background_rate": 0.005,
    }
})  # fmt: skip
# An optogenetic actuator: an action is a 1 ms light pulse on ChR2 (5 mW/mm^2 at the fibre).
VARIANTS.register("spikectl/NeuronControlChR2-v0", {"extensions": {"actuator": "chr2"}})
# Spikes-only sensing: the agent observes which neurons spiked, not their potentials.
VARIANTS.register("spikectl/NeuronControlSpikesOnly-v0", {"extensions": {"sensing": "spikes"}})
# The rig's loop at once: ChR2 light, 2 steps of latency, spikes-only sensing, and the
# spontaneous inputs that stand for the rig's noise (the realistic background rate:
# measurement noise acts on potentials, which spikes-only sensing does not report).
VARIANTS.register("spikectl/NeuronControlRig-v0", {
    "extensions": {
        "actuator": "chr2",
        "latency_steps": 2,
        "sensing": "spikes",
        "background_rate": 0.005,
    }
})  # fmt: skip


def flat_id(env_id: str) -> str:
    """The flat twin of a paper id: ``spikectl/NeuronControlNoisy-v0`` ->
    ``spikectl/NeuronControlNoisyFlat-v0``."""
    name, version = env_id.rsplit("-", 1)
    return f"{name}Flat-{version}"


FINAL_INFO_WRAPPER = "spikectl.wrappers.final_info:FinalInfoEpisodeStatistics"
"""The wrapper of each flat id's FinalInfo twin (imported when a twin is made)."""


def final_info_id(env_id: str) -> str:
    """The FinalInfo twin of a flat id: ``spikectl/NeuronControlNoisyFlat-v0`` ->
    ``spikectl/NeuronControlNoisyFlatFinalInfo-v0`` (the flat environment with
    ``info["final_info"]`` as Gymnasium < 1.0 gave it, docs/ecosystem.md)."""
    name, version = env_id.rsplit("-", 1)
    return f"{name}FinalInfo-{version}"


def registered_kwargs(env_id: str) -> dict[str, Any]:
    """The keyword arguments of a paper id (``{}`` for :data:`ENV_ID`); an unknown id is a
    one-line RegistryError listing the variants."""
    return {} if env_id == ENV_ID else dict(VARIANTS.entry(env_id))


def register_env_variant(env_id: str, kwargs: Mapping[str, Any]) -> None:
    """Register ``env_id`` (``"namespace/Name-vN"``) as the paper's environment with
    ``kwargs`` (JSON-ready keyword arguments of :class:`~spikectl.envs.env.NeuronControlEnv`),
    its flat twin :func:`flat_id` with the same ones and the flat twin's
    :func:`final_info_id`; all are then ``gymnasium.make``-able. The same variant
    registered again is a no-op; other kwargs under a taken id are a RegistryError."""
    from spikectl.envs.env import NeuronControlEnv

    if not _is_variant_id(env_id):
        raise RegistryError(
            f"an environment variant's id reads 'namespace/Name-vN' with a name not ending "
            f"in 'Flat' (its flat twin adds that), got {env_id!r}"
        )
    if not isinstance(kwargs, Mapping):
        raise RegistryError(f"a variant's kwargs must be a dict, got {type(kwargs).__name__}")
    known = set(inspect.signature(NeuronControlEnv).parameters)
    unknown = sorted(set(kwargs) - known)
    if unknown:
        raise RegistryError(
            f"variant {env_id!r}: {', '.join(unknown)} not an argument of NeuronControlEnv "
            f"({', '.join(sorted(known))})"
        )
    try:
        kwargs = json.loads(json.dumps(dict(kwargs)))
    except (TypeError, ValueError) as error:
        raise RegistryError(f"variant {env_id!r}: kwargs must be JSON-ready ({error})") from None
    VARIANTS.register(env_id, kwargs)
    _register_ids(env_id, kwargs)


def _is_variant_id(env_id: object) -> bool:
    from gymnasium.envs.registration import parse_env_id

    try:
        _, name, version = parse_env_id(env_id)
    except (gymnasium.error.Error, TypeError):
        return False
    return version is not None and not name.endswith("Flat")


def _register_ids(env_id: str, kwargs: dict[str, Any]) -> None:
    """A paper id, its flat twin and the flat twin's FinalInfo twin, with one ``kwargs``.

    A FinalInfo twin has no vector entry point (Gymnasium applies no wrapper to one), so
    ``gymnasium.make_vec`` of it is a ``SyncVectorEnv`` of wrapped flat environments,
    whose infos carry ``final_info`` as Gymnasium < 1.0's did."""
    from gymnasium.envs.registration import WrapperSpec

    flat = flat_id(env_id)
    twin = WrapperSpec(name="FinalInfoEpisodeStatistics", entry_point=FINAL_INFO_WRAPPER,
                       kwargs={})  # fmt: skip
    for id_, (entry_point, vector_entry_point), wrappers in (
        (env_id, PAPER_ENTRY_POINTS, ()),
        (flat, FLAT_ENTRY_POINTS, ()),
        (final_info_id(flat), (FLAT_ENTRY_POINTS[0], None), (twin,)),
    ):
        # Registering an id twice makes Gymnasium warn, and the package may be re-imported.
        if id_ not in gymnasium.registry:
            gymnasium.register(id=id_, entry_point=entry_point, kwargs=kwargs,
                               vector_entry_point=vector_entry_point,
                               additional_wrappers=wrappers)  # fmt: skip


def register_envs() -> None:
    """Register ``spikectl/NeuronControl-v0``, the library's variants (:data:`VARIANTS`),
    their flat twins (:data:`FLAT_ENV_ID`, ...) and the flat ids' FinalInfo twins
    (:func:`final_info_id`); idempotent.

    ``gymnasium.make(ENV_ID, **kwargs)`` builds :class:`spikectl.envs.env.NeuronControlEnv`;
    ``gymnasium.make_vec(ENV_ID, num_envs=...)`` builds the batched
    :class:`spikectl.envs.vector_env.NeuronControlVectorEnv` by default (Gymnasium prefers a
    registered vector entry point when ``vectorization_mode`` is None), and a
    ``SyncVectorEnv`` of single environments with ``vectorization_mode="sync"``. The
    variants are the same classes with the keyword arguments of :data:`VARIANTS`
    (arguments given to ``make`` override them).

    The paper ids are strict: an action outside the mask raises, so Gymnasium's "sync"
    and "async" vector modes (whose batched ``action_space.sample()`` knows no mask) need
    masked sampling, ``envs.action_space.sample(mask=tuple(infos["action_mask"]))``.
    The flat ids take any action of their spaces (an illegal one does nothing), and
    ``make_vec`` builds :class:`spikectl.wrappers.flat_vector_env.FlatNeuronControlVectorEnv`
    on the batched simulator; see docs/ecosystem.md.
    """
    _register_ids(ENV_ID, {})
    for env_id in VARIANTS:
        _register_ids(env_id, VARIANTS.entry(env_id))
