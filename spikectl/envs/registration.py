"""Gymnasium registration of the environment ids."""

from __future__ import annotations

from typing import Any

import gymnasium

ENV_ID = "spikectl/NeuronControl-v0"

VARIANTS: dict[str, dict[str, Any]] = {
    # Measurement noise on the observed potentials (docs/extensions.md).
    "spikectl/NeuronControlNoisy-v0": {"extensions": {"observation_noise_mV": 2.0}},
    # A quarter of the neurons (2 of 8) hidden: neither observed nor stimulable.
    "spikectl/NeuronControlPartial-v0": {"extensions": {"hidden_fraction": 0.25}},
    # A larger network: 32 neurons, the same topology rule.
    "spikectl/NeuronControl32-v0": {"n_neurons": 32},
    # Every extension at once, at moderate strength.
    "spikectl/NeuronControlRealistic-v0": {
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
    },
}
"""Registered variants: id -> keyword arguments (JSON-ready, so specs serialise)."""

FLAT_ENV_ID = "spikectl/NeuronControlFlat-v0"
"""The paper's task in generic RL libraries' conventions (spikectl.wrappers.flat_env)."""


def flat_id(env_id: str) -> str:
    """The flat twin of a paper id: ``spikectl/NeuronControlNoisy-v0`` ->
    ``spikectl/NeuronControlNoisyFlat-v0``."""
    name, version = env_id.rsplit("-", 1)
    return f"{name}Flat-{version}"


FLAT_VARIANTS: dict[str, dict[str, Any]] = {flat_id(i): kwargs for i, kwargs in VARIANTS.items()}
"""The flat twins of :data:`VARIANTS`: the same keyword arguments."""


def register_envs() -> None:
    """Register ``spikectl/NeuronControl-v0``, its :data:`VARIANTS` and their flat twins
    (:data:`FLAT_ENV_ID`, :data:`FLAT_VARIANTS`); idempotent.

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
    paper = (
        "spikectl.envs.env:NeuronControlEnv",
        "spikectl.envs.vector_env:NeuronControlVectorEnv",
    )
    flat = (
        "spikectl.wrappers.flat_env:FlatNeuronControlEnv",
        "spikectl.wrappers.flat_vector_env:FlatNeuronControlVectorEnv",
    )
    ids = [(i, kwargs, paper) for i, kwargs in {ENV_ID: {}, **VARIANTS}.items()]
    ids += [(i, kwargs, flat) for i, kwargs in {FLAT_ENV_ID: {}, **FLAT_VARIANTS}.items()]
    for env_id, kwargs, (entry_point, vector_entry_point) in ids:
        # Registering an id twice makes Gymnasium warn, and the package may be re-imported.
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point=entry_point,
            vector_entry_point=vector_entry_point,
            kwargs=kwargs,
        )
