"""Gymnasium registration of the environment ids."""

from __future__ import annotations

import gymnasium

ENV_ID = "spikectl/NeuronControl-v0"


def register_envs() -> None:
    """Register ``spikectl/NeuronControl-v0`` (single and vector entry points); idempotent.

    ``gymnasium.make(ENV_ID, **kwargs)`` builds :class:`spikectl.env.NeuronControlEnv`;
    ``gymnasium.make_vec(ENV_ID, num_envs=...)`` builds the batched
    :class:`spikectl.vector_env.NeuronControlVectorEnv` by default (Gymnasium prefers a
    registered vector entry point when ``vectorization_mode`` is None), and a
    ``SyncVectorEnv`` of single environments with ``vectorization_mode="sync"``.
    """
    # Registering an id twice makes Gymnasium warn, and the package may be re-imported.
    if ENV_ID in gymnasium.registry:
        return
    gymnasium.register(
        id=ENV_ID,
        entry_point="spikectl.env:NeuronControlEnv",
        vector_entry_point="spikectl.vector_env:NeuronControlVectorEnv",
    )
