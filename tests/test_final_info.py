"""The FinalInfo ids (spikectl/NeuronControlFlatFinalInfo-v0 and twins): episode
statistics in ``final_info``, where scripts written for Gymnasium < 1.0 read them, on
top of the flat environment, which is otherwise unchanged."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import SyncVectorEnv

import spikectl  # noqa: F401  (registers the ids)
from spikectl.envs.registration import FLAT_ENV_ID, VARIANTS, flat_id, register_envs
from spikectl.wrappers import (
    FinalInfo,
    FinalInfoEpisodeStatistics,
    FlatNeuronControlEnv,
    final_info_id,
)

SMALL = {"contexts": {"n_train": 10, "n_test": 10}}  # ten networks a split
FLAT_IDS = [FLAT_ENV_ID, *(flat_id(paper_id) for paper_id in VARIANTS)]
TWIN = final_info_id(FLAT_ENV_ID)


def test_every_flat_id_has_a_twin_with_its_arguments_and_the_wrapper():
    assert TWIN == "spikectl/NeuronControlFlatFinalInfo-v0"
    assert final_info_id("spikectl/NeuronControlNoisyFlat-v0") == (
        "spikectl/NeuronControlNoisyFlatFinalInfo-v0"
    )
    for env_id in FLAT_IDS:
        flat, twin = gym.spec(env_id), gym.spec(final_info_id(env_id))
        assert (twin.entry_point, twin.kwargs) == (flat.entry_point, flat.kwargs)
        assert [w.name for w in twin.additional_wrappers] == ["FinalInfoEpisodeStatistics"]
        assert twin.vector_entry_point is None  # Gymnasium wraps no vector entry point
    twins = [i for i in gym.registry if i.startswith("spikectl/") and "FinalInfo" in i]
    assert sorted(twins) == sorted(final_info_id(i) for i in FLAT_IDS)


def test_registering_again_changes_nothing():
    before = {i: gym.spec(i) for i in gym.registry}
    register_envs()
    assert {i: gym.spec(i) for i in gym.registry} == before


def test_the_twin_plays_the_flat_episode_and_ends_it_with_its_return_and_length():
    """Same seed, same (unmasked random) actions: the twin's observations, rewards and
    ends are the flat id's; only the last step's info gains final_info, holding the sum
    of the episode's rewards and its number of steps."""
    twin, flat = gym.make(TWIN, **SMALL), gym.make(FLAT_ENV_ID, **SMALL)
    assert isinstance(twin, FinalInfoEpisodeStatistics)
    assert isinstance(twin.unwrapped, FlatNeuronControlEnv)
    rng = np.random.default_rng(0)
    for episode in range(2):
        seed = None if episode else 3
        obs_twin, info_twin = twin.reset(seed=seed)
        obs_flat, info_flat = flat.reset(seed=seed)
        np.testing.assert_array_equal(obs_twin, obs_flat)
        assert "final_info" not in info_twin
        rewards, done = [], False
        while not done:
            action = int(rng.integers(twin.action_space.n))
            obs_twin, r_twin, term_twin, trunc_twin, info_twin = twin.step(action)
            obs_flat, r_flat, term_flat, trunc_flat, info_flat = flat.step(action)
            np.testing.assert_array_equal(obs_twin, obs_flat)
            assert (r_twin, term_twin, trunc_twin) == (r_flat, term_flat, trunc_flat)
            rewards.append(r_twin)
            done = term_twin or trunc_twin
            if not done:
                assert "final_info" not in info_twin
        final = info_twin.pop("final_info")
        assert info_twin.keys() == info_flat.keys()
        assert isinstance(final, FinalInfo) and not isinstance(final, dict)
        assert final["episode"]["l"] == len(rewards) == twin.unwrapped.env.episode_length
        assert final["episode"]["r"] == pytest.approx(sum(rewards), abs=1e-12)
        assert 0.0 <= final["episode"]["r"] <= 1.0


def test_sync_vector_infos_read_as_gymnasium_0_29_wrote_them():
    """CleanRL's loop, as published, over Gymnasium 1.x's SyncVectorEnv of the twin (plus
    Gymnasium's RecordEpisodeStatistics, as the scripts add): one episodic return per
    ended sub-environment, at the step it ended, and None for the others."""

    def make():
        return gym.wrappers.RecordEpisodeStatistics(gym.make(TWIN, **SMALL))

    envs = SyncVectorEnv([make, make, make])
    envs.reset(seed=0)
    envs.action_space.seed(0)
    logged, steps = [], 0
    while steps < 130:  # two episodes of 60 steps each and the autoreset steps between
        _, _, terminated, _, infos = envs.step(envs.action_space.sample())
        steps += 1
        if "final_info" in infos:
            assert infos["final_info"].dtype == object
            np.testing.assert_array_equal(infos["_final_info"], terminated)
            for info in infos["final_info"]:
                if info and "episode" in info:
                    logged.append((steps, info["episode"]["r"], info["episode"]["l"]))
            ended = np.flatnonzero(terminated)
            returns = infos["episode"]["r"][ended]  # Gymnasium 1.x's own statistics
            np.testing.assert_allclose([r for _, r, _ in logged[-len(ended):]], returns)
        else:
            assert not terminated.any()
    # Each sub-environment ends at step 60, is reset at step 61, ends again at step 121.
    assert [(step, length) for step, _, length in logged] == [(60, 60)] * 3 + [(121, 60)] * 3


def test_make_vec_of_the_twin_is_a_sync_vector_env_of_wrapped_flat_environments():
    envs = gym.make_vec(TWIN, 2, **SMALL)
    assert isinstance(envs, SyncVectorEnv)
    assert all(isinstance(env, FinalInfoEpisodeStatistics) for env in envs.envs)


def test_final_info_is_a_picklable_read_only_mapping():
    """Picklable, so that AsyncVectorEnv can send it between processes."""
    final = FinalInfo({"episode": {"r": 0.5, "l": 60}})
    assert dict(pickle.loads(pickle.dumps(final))) == {"episode": {"r": 0.5, "l": 60}}
    assert len(final) == 1 and list(final) == ["episode"]
    with pytest.raises(TypeError):
        final["episode"] = {}  # type: ignore[index]
    assert repr(final) == "FinalInfo({'episode': {'r': 0.5, 'l': 60}})"
