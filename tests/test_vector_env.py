"""NeuronControlVectorEnv: equal to single environments and to SyncVectorEnv, in one batch."""

from __future__ import annotations

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import batch_space

import spikectl.envs.vector_env
from spikectl.contexts import make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.registration import ENV_ID
from spikectl.envs.vector_env import NeuronControlVectorEnv

SMALL = {"contexts": {"n_train": 10, "n_test": 10}}
INFO_KEYS = ("action_mask", "context_index", "spikes", "target_spiked")


def legal_actions(rng: np.random.Generator, masks: np.ndarray) -> np.ndarray:
    return np.array([rng.choice(np.flatnonzero(mask)) - 1 for mask in masks])


def assert_observations_equal(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert a[key].dtype == b[key].dtype, key
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def assert_infos_equal(a: dict, b: dict) -> None:
    """Equal wherever Gymnasium's ``_key`` masks say the value is present."""
    absent = np.zeros(len(a["_action_mask"]), dtype=bool)
    for key in INFO_KEYS:
        present = b.get(f"_{key}", absent)
        np.testing.assert_array_equal(a.get(f"_{key}", absent), present, err_msg=f"_{key}")
        if present.any():
            np.testing.assert_array_equal(a[key][present], b[key][present], err_msg=key)


def test_spaces_are_the_single_spaces_batched():
    envs = NeuronControlVectorEnv(num_envs=3, **SMALL)
    single = NeuronControlEnv(**SMALL)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    assert envs.observation_space == batch_space(single.observation_space, 3)
    assert envs.action_space == batch_space(single.action_space, 3)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    obs, _ = envs.reset(seed=0)
    assert obs in envs.observation_space
    assert envs.step(envs.action_space.sample())[0] in envs.observation_space


def test_equals_single_envs_step_by_step():
    contexts = [3, 1, 4, 1, 5]
    envs = NeuronControlVectorEnv(num_envs=len(contexts), **SMALL)
    singles = [NeuronControlEnv(**SMALL) for _ in contexts]
    obs, infos = envs.reset(options={"context": contexts})
    for i, single in enumerate(singles):
        single_obs, single_info = single.reset(options={"context": contexts[i]})
        for key in obs:
            np.testing.assert_array_equal(obs[key][i], single_obs[key])
        np.testing.assert_array_equal(infos["action_mask"][i], single_info["action_mask"])
    rng = np.random.default_rng(0)
    for _ in range(single.episode_length):
        actions = legal_actions(rng, infos["action_mask"])
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        for i, single in enumerate(singles):
            single_obs, reward, done, cut, info = single.step(int(actions[i]))
            for key in obs:
                np.testing.assert_array_equal(obs[key][i], single_obs[key], err_msg=key)
            assert (rewards[i], terminated[i], truncated[i]) == (reward, done, cut)
            for key in INFO_KEYS:
                np.testing.assert_array_equal(infos[key][i], info[key], err_msg=key)
    assert terminated.all()


def test_equals_sync_vector_env_across_autoresets():
    num_envs = 4
    batched = gym.make_vec(ENV_ID, num_envs=num_envs, episode_length=12, **SMALL)
    sync = gym.make_vec(
        ENV_ID, num_envs=num_envs, vectorization_mode="sync", episode_length=12, **SMALL
    )
    assert isinstance(batched, NeuronControlVectorEnv) and isinstance(sync, SyncVectorEnv)
    rng = np.random.default_rng(1)
    obs_a, info_a = batched.reset(seed=11)
    obs_b, info_b = sync.reset(seed=11)
    assert_observations_equal(obs_a, obs_b)
    assert_infos_equal(info_a, info_b)
    autoresets = 0
    for _ in range(3 * 13 + 4):  # more than three episodes with their autoreset steps
        actions = legal_actions(rng, info_a["action_mask"])
        resetting = np.flatnonzero(obs_a["step"] == 12)
        # The action of an env being autoreset is ignored, even an illegal one.
        actions[resetting] = obs_a["target"][resetting]
        autoresets += resetting.size
        obs_a, rewards_a, terminated_a, truncated_a, info_a = batched.step(actions)
        obs_b, rewards_b, terminated_b, truncated_b, info_b = sync.step(actions)
        assert_observations_equal(obs_a, obs_b)
        np.testing.assert_array_equal(rewards_a, rewards_b)
        assert rewards_a.dtype == rewards_b.dtype
        np.testing.assert_array_equal(terminated_a, terminated_b)
        np.testing.assert_array_equal(truncated_a, truncated_b)
        assert_infos_equal(info_a, info_b)
    assert autoresets == 3 * num_envs


def test_reset_mask_resets_only_the_marked_envs():
    envs = NeuronControlVectorEnv(num_envs=3, **SMALL)
    sync = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="sync", **SMALL)
    for vector_env in (envs, sync):
        vector_env.reset(seed=2)
        vector_env.step(np.full(3, -1))
    mask = np.array([True, False, True])
    obs_a, info_a = envs.reset(seed=5, options={"reset_mask": mask})
    obs_b, info_b = sync.reset(seed=5, options={"reset_mask": mask.copy()})
    assert_observations_equal(obs_a, obs_b)
    np.testing.assert_array_equal(obs_a["step"], [0, 1, 0])
    np.testing.assert_array_equal(info_a["_context_index"], mask)
    np.testing.assert_array_equal(info_a["context_index"][mask], info_b["context_index"][mask])
    for bad in (np.array([1, 0, 1]), np.zeros(3, dtype=bool), [True, False, True]):
        with pytest.raises(ValueError, match="reset_mask"):
            envs.reset(options={"reset_mask": bad})


def test_seed_lists():
    envs = NeuronControlVectorEnv(num_envs=3, **SMALL)
    drawn = envs.reset(seed=5)[1]["context_index"]
    np.testing.assert_array_equal(envs.reset(seed=[5, 6, np.int64(7)])[1]["context_index"], drawn)
    with pytest.raises(ValueError, match="num_envs=3"):
        envs.reset(seed=[1, 2])


BAD_SEEDS = [  # (seed, a regular expression its message must match)
    (0.5, r"got 0\.5 \(float\)"), (True, r"got True \(bool\)"), ("x", r"got 'x' \(str\)"),
    (-1, "got -1$"), ([0.5, 1.7, 2.9], r"^seed\[0\] .* got 0\.5 \(float\)"),
    ({0: 1, 1: 2, 2: 3}, r"got \{0: 1, 1: 2, 2: 3\} \(dict\)"), ([1, 2], "got a list of 2$"),
    ([1, None, -3], r"^seed\[2\] .* got -3$"), (np.zeros(3), r"got array\(.*\(ndarray\)"),
    (list(range(10**6)), "got a list of 1000000$"),
]  # fmt: skip


@pytest.mark.parametrize("env_id", [ENV_ID, "spikectl/NeuronControlFlat-v0"])
def test_a_bad_seed_is_one_named_error_naming_it(env_id):
    from spikectl.envs.env_arguments import SeedError

    envs = gym.make_vec(env_id, 3, **SMALL)
    for seed, given in BAD_SEEDS:
        with pytest.raises(SeedError, match=given) as caught:
            envs.reset(seed=seed)
        assert str(caught.value).startswith("seed") and len(str(caught.value)) < 300
        assert isinstance(caught.value, ValueError) and isinstance(caught.value, TypeError)


def test_numpy_integer_seeds_give_what_python_ones_give():
    envs = gym.make_vec(ENV_ID, 3, **SMALL)
    drawn = envs.reset(seed=3)[1]["context_index"]
    for seed in (np.int64(3), np.uint8(3), [3, np.int32(4), 5], (3, 4, 5), np.arange(3, 6)):
        np.testing.assert_array_equal(envs.reset(seed=seed)[1]["context_index"], drawn)
    mixed = envs.reset(seed=[np.int64(3), None, 5])[1]["context_index"]
    assert mixed[0] == drawn[0] and mixed[2] == drawn[2]


def test_make_vec_builds_the_batched_env():
    for mode in (None, "vector_entry_point"):
        envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode=mode, n_neurons=5, **SMALL)
        assert isinstance(envs, NeuronControlVectorEnv)
        assert (envs.num_envs, envs.n_neurons) == (2, 5)


def test_one_simulator_call_per_step(monkeypatch):
    calls = []
    original = spikectl.envs.vector_env.advance

    def counting_advance(state, weights, actions, *args):
        calls.append((weights.shape, actions.shape))
        original(state, weights, actions, *args)

    monkeypatch.setattr(spikectl.envs.vector_env, "advance", counting_advance)
    envs = NeuronControlVectorEnv(num_envs=6, episode_length=5, **SMALL)
    envs.reset(seed=0)
    for _ in range(12):  # two episodes and two autoreset steps
        envs.step(np.full(6, -1))
    assert calls == [((6, 8, 8), (6, 1))] * 12


def test_batched_evaluation_over_a_whole_set():
    train, _ = make_splits(12, 1, seed=4)
    envs = NeuronControlVectorEnv(num_envs=len(train), contexts=train)
    for actions, expected in ((None, 0.5), ("witness", 1.0)):
        obs, infos = envs.reset(options={"context": list(range(len(train)))})
        np.testing.assert_array_equal(infos["context_index"], np.arange(len(train)))
        np.testing.assert_array_equal(obs["target"], [c.target for c in train])
        witnesses = np.stack([c.witness for c in train])
        returns = np.zeros(len(train))
        for t in range(train.episode_length):
            step_actions = np.full(len(train), -1) if actions is None else witnesses[:, t]
            _, rewards, terminated, _, _ = envs.step(step_actions)
            returns += rewards
        assert terminated.all()
        assert all(math.isclose(r, expected, rel_tol=0, abs_tol=1e-12) for r in returns)


def test_context_objects_as_reset_options():
    train, test = make_splits(5, 3, seed=0)
    envs = NeuronControlVectorEnv(num_envs=3, contexts=train)
    obs, infos = envs.reset(options={"context": test})  # another set's contexts, one each
    np.testing.assert_array_equal(obs["target"], [c.target for c in test])
    obs, infos = envs.reset(options={"context": test[1]})
    np.testing.assert_array_equal(infos["context_index"], [-1, -1, -1])
    np.testing.assert_array_equal(obs["target"], [test[1].target] * 3)
    obs, infos = envs.reset(options={"context": [test[0], 4, np.int64(2)]})
    np.testing.assert_array_equal(infos["context_index"], [-1, 4, 2])
    np.testing.assert_array_equal(obs["pattern"][0], test[0].pattern)
    with pytest.raises(ValueError, match="num_envs=3"):
        envs.reset(options={"context": [1, 2]})
    with pytest.raises(ValueError, match=r"env 2: context index"):
        envs.reset(options={"context": [1, 2, 9]})
    with pytest.raises(TypeError, match="context option"):
        envs.reset(options={"context": "train"})
    small, _ = make_splits(1, 1, n_neurons=4, seed=0)
    with pytest.raises(ValueError, match="4 neurons"):
        envs.reset(options={"context": small[0]})


def test_illegal_actions_name_the_env():
    envs = NeuronControlVectorEnv(num_envs=3, **SMALL)
    obs, _ = envs.reset(seed=0)
    actions = np.full(3, -1)
    actions[1] = obs["target"][1]
    with pytest.raises(ValueError, match=rf"1 of 3 actions are illegal \(env 1: action "
                       rf"{actions[1]}\): an action that stimulates the target"):  # fmt: skip
        envs.step(actions)
    with pytest.raises(ValueError, match=r"1 of 3 actions are out of range \(env 2: action 8\)"):
        envs.step(np.array([-1, -1, 8]))
    for bad in (np.full(2, -1), np.full(3, -1.0), -1):
        with pytest.raises(ValueError, match=r"integers of shape \(3,\)"):
            envs.step(bad)
    np.testing.assert_array_equal(envs.step([-1, -1, -1])[0]["step"], [1, 1, 1])


def test_bad_actions_among_many_environments_make_a_short_message():
    envs = NeuronControlVectorEnv(num_envs=20_000, **SMALL)
    obs, _ = envs.reset(seed=0)
    actions = np.full(20_000, -1)
    actions[[7, 12_345]] = 99
    with pytest.raises(ValueError) as caught:
        envs.step(actions)
    message = str(caught.value)
    assert message.startswith("2 of 20,000 actions are out of range (env 7: action 99, env 12345:")
    assert "0..7" in message and len(message) < 300, message
    actions = obs["target"].copy()  # every environment's target: all illegal
    with pytest.raises(ValueError) as caught:
        envs.step(actions)
    message = str(caught.value)
    assert message.startswith("20,000 of 20,000 actions are illegal (env 0: action ")
    assert "19,995 more" in message and len(message) < 400, message
    with pytest.raises(ValueError, match=r"got float64 \(20000,\)$"):
        envs.step(np.zeros(20_000))


def test_allow_target_action():
    envs = NeuronControlVectorEnv(num_envs=2, extensions={"allow_target_action": True}, **SMALL)
    obs, infos = envs.reset(seed=0)
    assert infos["action_mask"].all()
    _, _, _, _, infos = envs.step(obs["target"])
    assert infos["target_spiked"].all()


def test_action_space_samples_only_legal_actions():
    envs = NeuronControlVectorEnv(num_envs=16, **SMALL)
    envs.action_space.seed(0)
    _, infos = envs.reset(seed=0)
    for _ in range(30):
        actions = envs.action_space.sample()
        assert infos["action_mask"][np.arange(16), actions + 1].all()
        _, _, _, _, infos = envs.step(actions)


def test_step_before_reset_raises():
    envs = NeuronControlVectorEnv(num_envs=2, **SMALL)
    with pytest.raises(ResetNeeded):
        envs.step(np.full(2, -1))
    envs.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(ResetNeeded, match=r"\[1\] were never reset"):
        envs.step(np.full(2, -1))


def test_bad_constructor_arguments():
    for num_envs in (0, 1.5, True):
        with pytest.raises(ValueError, match="num_envs"):
            NeuronControlVectorEnv(num_envs=num_envs, **SMALL)
    with pytest.raises(ValueError, match="render_mode"):
        NeuronControlVectorEnv(num_envs=2, render_mode="human", **SMALL)
    with pytest.raises(ValueError, match="split"):
        NeuronControlVectorEnv(num_envs=2, split="dev", **SMALL)


def test_pickled_vector_env_continues_identically():
    envs = NeuronControlVectorEnv(num_envs=3, episode_length=10, **SMALL)
    rng = np.random.default_rng(0)
    _, infos = envs.reset(seed=1)
    for _ in range(7):
        _, _, _, _, infos = envs.step(legal_actions(rng, infos["action_mask"]))
    clone = pickle.loads(pickle.dumps(envs))
    for _ in range(15):  # across an autoreset
        actions = legal_actions(rng, infos["action_mask"])
        obs, rewards, terminated, _, infos = envs.step(actions)
        clone_obs, clone_rewards, clone_terminated, _, _ = clone.step(actions)
        assert_observations_equal(obs, clone_obs)
        np.testing.assert_array_equal(rewards, clone_rewards)
        np.testing.assert_array_equal(terminated, clone_terminated)


def test_the_sb3_adapter_s_bad_actions_make_a_short_message():
    pytest.importorskip("stable_baselines3")
    from spikectl.wrappers import sb3_vec_env

    for illegal_action in ("do_nothing", "raise"):
        venv = sb3_vec_env(gym.make_vec(ENV_ID, 20_000, **SMALL), illegal_action=illegal_action)
        venv.reset()
        actions = np.zeros(20_000, dtype=np.int64)
        actions[[4, 15_000]] = [9, -1]
        with pytest.raises(ValueError) as caught:
            venv.step(actions)
        message = str(caught.value)
        assert message.startswith("2 of 20,000 actions are out of range (env 4: action 9, "
                                  "env 15000: action -1): actions must be integers in 0..8")
        assert len(message) < 300, message
    targets = np.argmin(venv.action_masks(), axis=1)  # every environment's target: illegal
    with pytest.raises(ValueError) as caught:
        venv.step(targets)
    message = str(caught.value)
    assert message.startswith("20,000 of 20,000 actions are illegal (env 0: action ")
    assert "19,995 more" in message and len(message) < 400, message
