"""The flat ids (spikectl/NeuronControlFlat-v0 and twins): the conventions generic RL
libraries take as they are, on the paper's dynamics, batched under make_vec."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv

import spikectl  # noqa: F401  (registers the ids)
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.registration import ENV_ID, FLAT_ENV_ID, VARIANTS, flat_id
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers import FlatNeuronControlEnv, FlatNeuronControlVectorEnv, FlatObservation

SMALL = {"contexts": {"n_train": 10, "n_test": 10}}
FLAT_IDS = [FLAT_ENV_ID, *map(flat_id, VARIANTS)]


def test_every_paper_id_has_a_flat_twin_with_its_arguments():
    assert flat_id(ENV_ID) == FLAT_ENV_ID
    assert flat_id("spikectl/NeuronControlNoisy-v0") == "spikectl/NeuronControlNoisyFlat-v0"
    for paper_id in VARIANTS:
        spec = gym.spec(flat_id(paper_id))
        assert spec.kwargs == VARIANTS.entry(paper_id) == gym.spec(paper_id).kwargs
        assert spec.vector_entry_point.endswith(":FlatNeuronControlVectorEnv")


@pytest.mark.parametrize("env_id", FLAT_IDS)
def test_spaces_are_zero_based_and_finitely_bounded(env_id):
    env = gym.make(env_id, **SMALL)
    k, length = env.unwrapped.env.n_observed, env.unwrapped.env.episode_length
    assert env.action_space == gym.spaces.Discrete(k + 1)  # start 0: 0 = do nothing
    space = env.observation_space
    assert isinstance(space, gym.spaces.Box) and space.dtype == np.float32
    # With loop latency L the actions in flight follow, one-hot: L (k + 1) entries.
    latency = env.unwrapped.env.extensions.latency_steps
    assert space.shape == (3 * k + 3 * length + 2 + latency * (k + 1),)
    assert np.isfinite(space.low).all() and np.isfinite(space.high).all()
    assert (space.low[k:] >= -1).all() and (space.high[k:] <= 1).all()


@pytest.mark.parametrize("env_id", [FLAT_ENV_ID, "spikectl/NeuronControlRealisticFlat-v0"])
def test_observations_stay_in_the_bounds_on_random_episodes(env_id):
    """Unmasked random actions (illegal ones included) for three episodes: every observation
    is in the space, with measurement noise and background input too (clipped)."""
    env = gym.make(env_id, **SMALL)
    env.action_space.seed(0)
    obs, info = env.reset(seed=0)
    episodes = 0
    while episodes < 3:
        assert obs in env.observation_space
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        if terminated or truncated:
            episodes += 1
            assert obs in env.observation_space
            obs, info = env.reset()


def test_action_a_plus_one_is_the_paper_action_a_step_for_step():
    flat = gym.make(FLAT_ENV_ID, **SMALL)
    paper = NeuronControlEnv(**SMALL)
    codec = flat.unwrapped.observation_codec
    rng = np.random.default_rng(4)
    for seed in (1, 2):
        obs, info = flat.reset(seed=seed)
        paper_obs, paper_info = paper.reset(seed=seed)
        assert info["context_index"] == paper_info["context_index"]
        np.testing.assert_array_equal(obs, codec(paper_obs))
        for _ in range(paper.episode_length):
            paper_action = int(rng.choice(np.flatnonzero(paper_info["action_mask"]))) - 1
            obs, reward, terminated, truncated, info = flat.step(paper_action + 1)
            paper_obs, paper_reward, paper_done, _, paper_info = paper.step(paper_action)
            np.testing.assert_array_equal(obs, codec(paper_obs))
            assert (reward, terminated, truncated) == (paper_reward, paper_done, False)
            np.testing.assert_array_equal(info["spikes"], paper_info["spikes"])
            np.testing.assert_array_equal(info["action_mask"], paper_info["action_mask"])
            assert info["illegal_action"] is False
        assert terminated


def test_action_zero_does_nothing():
    flat = gym.make(FLAT_ENV_ID, **SMALL)
    paper = NeuronControlEnv(**SMALL)
    flat.reset(seed=5)
    paper.reset(seed=5)
    total = paper_total = 0.0
    for _ in range(paper.episode_length):
        obs, reward, *_ = flat.step(0)
        paper_obs, paper_reward, *_ = paper.step(-1)
        total, paper_total = total + reward, paper_total + paper_reward
        k = flat.unwrapped.observation_codec.k
        assert obs[2 * k] == 1.0  # last action one-hot: do nothing
    assert total == paper_total == pytest.approx(0.5)  # silence scores R_max


def test_an_illegal_action_does_nothing_and_is_counted():
    illegal_env, idle_env = gym.make(FLAT_ENV_ID, **SMALL), gym.make(FLAT_ENV_ID, **SMALL)
    _, info = illegal_env.reset(seed=7)
    idle_env.reset(seed=7)
    target_action = int(np.flatnonzero(info["action_mask"] == 0)[0])
    assert target_action >= 1  # a stimulation: do nothing (0) is always legal
    for count in range(1, 4):
        obs, reward, _, _, info = illegal_env.step(target_action)
        idle_obs, idle_reward, _, _, idle_info = idle_env.step(0)
        np.testing.assert_array_equal(obs, idle_obs)  # the same step as doing nothing ...
        assert reward == idle_reward
        assert info["illegal_action"] is True and info["illegal_actions"] == count  # ... counted
        assert idle_info["illegal_action"] is False and idle_info["illegal_actions"] == 0
    _, info = illegal_env.reset()
    assert info["illegal_actions"] == 0  # per episode


def test_strict_mode_raises_on_an_illegal_action():
    env = gym.make(FLAT_ENV_ID, illegal_action="raise", **SMALL)
    _, info = env.reset(seed=7)
    target_action = int(np.flatnonzero(info["action_mask"] == 0)[0])
    with pytest.raises(ValueError, match="stimulates the target neuron"):
        env.step(target_action)
    with pytest.raises(ValueError, match="illegal_action must be one of"):
        gym.make(FLAT_ENV_ID, illegal_action="ignore", **SMALL)
    env = gym.make(FLAT_ENV_ID, **SMALL)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action 9 is not in Discrete\(9\)"):
        env.step(9)


def test_action_masks_are_int8_on_every_id_and_feed_masked_sampling():
    for env in (gym.make(ENV_ID, **SMALL), gym.make(FLAT_ENV_ID, **SMALL)):
        _, info = env.reset(seed=0)
        for _ in range(20):
            assert info["action_mask"].dtype == np.int8
            env.action_space.seed(1)
            action = env.action_space.sample(mask=info["action_mask"])
            _, _, _, _, info = env.step(action)
            assert "illegal_action" not in info or info["illegal_action"] is False
    do_nothing = np.zeros(3, dtype=np.int64)
    for envs, actions in (
        (NeuronControlVectorEnv(3, **SMALL), do_nothing - 1),
        (gym.make_vec(FLAT_ENV_ID, 3, **SMALL), do_nothing),
    ):
        _, infos = envs.reset(seed=0)
        assert infos["action_mask"].dtype == np.int8
        _, _, _, _, infos = envs.step(actions)
        assert infos["action_mask"].dtype == np.int8


def test_gymnasium_check_env_is_silent_on_the_flat_env():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(FLAT_ENV_ID, **SMALL).unwrapped, skip_render_check=False)


def test_make_vec_gives_the_batched_simulator():
    envs = gym.make_vec(FLAT_ENV_ID, num_envs=4, **SMALL)
    assert isinstance(envs, FlatNeuronControlVectorEnv)
    assert isinstance(envs, NeuronControlVectorEnv)  # one batch, one advance() per step
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    single = FlatNeuronControlEnv(**SMALL)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    assert envs.spec.id == FLAT_ENV_ID


def make_three(num_envs: int, **kwargs):
    """The batched, sync and async vector environments of the flat id."""
    return [
        gym.make_vec(FLAT_ENV_ID, num_envs, vectorization_mode=mode, **kwargs)
        for mode in (None, "sync", "async")
    ]


def test_batched_sync_and_async_give_the_same_trajectories():
    """Same seeds, the same unmasked random actions (illegal ones and actions sent to
    environments being autoreset included): the same observations, rewards, ends, masks
    and illegal-action counts over several episodes."""
    num_envs = 3
    batched, sync, asynchronous = make_three(num_envs, episode_length=12, **SMALL)
    assert isinstance(sync, SyncVectorEnv) and isinstance(asynchronous, AsyncVectorEnv)
    rng = np.random.default_rng(2)
    results = [envs.reset(seed=11) for envs in (batched, sync, asynchronous)]
    illegal = 0
    try:
        for _ in range(3 * 13 + 2):
            for obs, info in results[1:]:
                np.testing.assert_array_equal(obs, results[0][0])
                for key in ("action_mask", "illegal_actions"):
                    np.testing.assert_array_equal(info[key], results[0][1][key], err_msg=key)
            actions = rng.integers(0, 9, size=num_envs)
            steps = [envs.step(actions) for envs in (batched, sync, asynchronous)]
            for step in steps[1:]:
                for a, b in zip(step[1:4], steps[0][1:4], strict=True):
                    np.testing.assert_array_equal(a, b)
            illegal += steps[0][4]["illegal_action"].sum()
            results = [(step[0], step[4]) for step in steps]
    finally:
        asynchronous.close()
    assert illegal > 0  # the random actions did hit the target neuron


def test_flat_batched_env_equals_the_paper_batched_env_shifted():
    flat = gym.make_vec(FLAT_ENV_ID, 4, **SMALL)
    paper = NeuronControlVectorEnv(4, **SMALL)
    codec = FlatObservation(8, 8, 60, paper.params)
    obs, infos = flat.reset(seed=3)
    paper_obs, paper_infos = paper.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(2 * 61):
        np.testing.assert_array_equal(obs, codec(paper_obs))
        legal = [np.flatnonzero(mask) - 1 for mask in paper_infos["action_mask"]]
        paper_actions = np.array([rng.choice(actions) for actions in legal])
        obs, rewards, terminated, _, infos = flat.step(paper_actions + 1)
        paper_obs, paper_rewards, paper_terminated, _, paper_infos = paper.step(paper_actions)
        np.testing.assert_array_equal(rewards, paper_rewards)
        np.testing.assert_array_equal(terminated, paper_terminated)
        assert not infos["illegal_action"].any()


def test_batched_actions_outside_the_space_raise_one_line():
    envs = gym.make_vec(FLAT_ENV_ID, 2, **SMALL)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"1 of 2 actions are out of range \(env 1: action 9\): "
                       r"actions must be integers in 0\.\.8"):  # fmt: skip
        envs.step(np.array([0, 9]))
    with pytest.raises(ValueError, match=r"actions must be integers in 0\.\.8 .*of shape \(2,\)"):
        envs.step(np.array([0.0, 1.0]))
    strict = gym.make_vec(FLAT_ENV_ID, 2, illegal_action="raise", **SMALL)
    _, infos = strict.reset(seed=0)
    actions = np.argmin(infos["action_mask"], axis=1)  # each environment's target
    with pytest.raises(ValueError, match="env 0: action .* stimulates the target neuron"):
        strict.step(actions)


def test_paper_id_in_sync_mode_survives_masked_random_actions():
    """The paper ids stay strict; Gymnasium's sync mode steps them with masked sampling."""
    envs = gym.make_vec(ENV_ID, 3, vectorization_mode="sync", episode_length=12, **SMALL)
    envs.action_space.seed(0)
    _, infos = envs.reset(seed=0)
    for _ in range(30):
        actions = envs.action_space.sample(mask=tuple(infos["action_mask"]))
        _, _, _, _, infos = envs.step(actions)


def test_autoreset_disabled_leaves_resets_to_the_caller():
    """TorchRL's mode: an ended environment is reset by reset(options={"reset_mask": ...})."""
    envs = gym.make_vec(FLAT_ENV_ID, 2, autoreset_mode="Disabled", episode_length=5, **SMALL)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.DISABLED
    obs, _ = envs.reset(seed=0)
    for _ in range(5):
        obs, _, terminated, _, _ = envs.step(np.zeros(2, dtype=np.int64))
    assert terminated.all()
    with pytest.raises(gym.error.ResetNeeded, match=r"sub-environment\(s\) \[0, 1\] ended"):
        envs.step(np.zeros(2, dtype=np.int64))
    first, infos = envs.reset(options={"reset_mask": np.array([True, False])})
    np.testing.assert_array_equal(infos["_action_mask"], [True, False])
    np.testing.assert_array_equal(first[1], obs[1])  # the other one kept its last state
    assert first[0, 3 * 8 + 1] == 1.0  # step 0
    with pytest.raises(ValueError, match="autoreset_mode must be"):
        gym.make_vec(FLAT_ENV_ID, 2, autoreset_mode="SameStep", **SMALL)


def test_bad_actions_among_many_flat_environments_make_a_short_message():
    envs = gym.make_vec(FLAT_ENV_ID, 20_000, **SMALL)
    envs.reset(seed=0)
    actions = np.zeros(20_000, dtype=np.int64)
    actions[[3, 12_345]] = [99, -4]
    with pytest.raises(ValueError) as caught:
        envs.step(actions)
    message = str(caught.value)
    assert message.startswith(
        "2 of 20,000 actions are out of range (env 3: action 99, env 12345: action -4): "
        "actions must be integers in 0..8"
    ), message
    assert len(message) < 300, message
    with pytest.raises(ValueError, match=r"got float64 \(20000,\)$"):
        envs.step(np.zeros(20_000))
    strict = gym.make_vec(FLAT_ENV_ID, 20_000, illegal_action="raise", **SMALL)
    _, infos = strict.reset(seed=0)
    with pytest.raises(ValueError) as caught:
        strict.step(np.argmin(infos["action_mask"], axis=1))  # every environment's target
    message = str(caught.value)
    assert message.startswith("20,000 of 20,000 actions are illegal (env 0: action ")
    assert "19,995 more" in message and len(message) < 400, message


@pytest.mark.parametrize("env_id", [ENV_ID, FLAT_ENV_ID])
def test_single_environment_seeds_follow_the_one_rule(env_id):
    from spikectl.envs import SeedError

    env = gym.make(env_id, **SMALL)
    first = env.reset(seed=3)[1]["context_index"]
    for seed in (np.int64(3), np.uint16(3)):
        assert env.reset(seed=seed)[1]["context_index"] == first
    for seed, given in ((0.5, r"got 0\.5 \(float\)$"), (True, r"got True \(bool\)$"),
                        (-1, "got -1$"), ([1, 2], r"got \[1, 2\] \(list\)$"),
                        ("x" * 10**6, r"got 'x{10,}\.\.\.x+' \(str\)$")):  # fmt: skip
        with pytest.raises(SeedError, match=given) as caught:
            env.reset(seed=seed)
        assert str(caught.value).startswith("seed must be") and len(str(caught.value)) < 200
