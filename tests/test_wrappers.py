"""spikectl.wrappers: the environment for Stable-Baselines3 and sb3-contrib.

The mapping, masks, bounds and layout are tested without SB3; the checks that need
SB3 (its check_env, the VecEnv adapter) are skipped when it is not installed
(``pip install -e ".[sb3]"``). MaskablePPO training is the slow test at the end.
"""

from __future__ import annotations

import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env

import spikectl
from spikectl.contexts import make_context
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.params import NeuronParams
from spikectl.wrappers import (
    DO_NOTHING,
    SB3CompatibleEnv,
    from_env_action,
    sb3_compatible,
    sb3_vec_env,
    to_env_action,
    voltage_bounds_mV,
)

ENV_ID = "spikectl/NeuronControl-v0"
SMALL = {"contexts": {"n_train": 10, "n_test": 10}}


def make(flatten: bool = True, illegal_action: str = "do_nothing", env_id=ENV_ID, **kwargs):
    return sb3_compatible(
        gym.make(env_id, **SMALL, **kwargs), flatten=flatten, illegal_action=illegal_action
    )


def test_exported_from_the_package():
    assert spikectl.sb3_compatible is spikectl.wrappers.sb3_compatible is sb3_compatible
    assert spikectl.sb3_vec_env is sb3_vec_env


def test_action_mapping_is_zero_based():
    assert to_env_action(0) == -1 and from_env_action(-1) == DO_NOTHING == 0
    assert to_env_action(3) == 2 and from_env_action(2) == 3
    actions = np.arange(9)
    np.testing.assert_array_equal(from_env_action(to_env_action(actions)), actions)


@pytest.mark.parametrize("flatten", [True, False])
def test_spaces(flatten):
    env = make(flatten)
    assert env.action_space == gym.spaces.Discrete(9)  # 0 = nothing, 1..8 = neurons 0..7
    if flatten:
        assert env.observation_space.shape == (3 * 8 + 3 * 60 + 2,)
        assert env.observation_space.dtype == np.float32
        assert np.isfinite(env.observation_space.low).all()
        assert np.isfinite(env.observation_space.high).all()
    else:
        space = env.observation_space
        assert space["last_action"] == gym.spaces.Discrete(9)
        assert space["voltage"].is_bounded("both")


def test_replays_the_base_environment_with_shifted_actions():
    """Same seed, actions a and a - 1: same rewards, spikes, contexts and voltages."""
    wrapped = make(flatten=False)
    base = NeuronControlEnv(**SMALL)
    obs, info = wrapped.reset(seed=3)
    base_obs, base_info = base.reset(seed=3)
    assert info["context_index"] == base_info["context_index"]
    rng = np.random.default_rng(0)
    for _ in range(base.episode_length):
        action = int(rng.choice(np.flatnonzero(wrapped.action_masks())))
        obs, reward, terminated, truncated, info = wrapped.step(action)
        base_obs, base_reward, base_terminated, _, base_info = base.step(action - 1)
        assert (reward, terminated, truncated) == (base_reward, base_terminated, False)
        np.testing.assert_array_equal(info["spikes"], base_info["spikes"])
        np.testing.assert_array_equal(obs["voltage"], base_obs["voltage"])
        assert obs["last_action"] == action == base_obs["last_action"] + 1
        assert not info["illegal_action"]
    assert terminated


def test_witness_scores_one_through_the_wrapper():
    context = make_context(
        np.array([[0, 0, 1], [0, 0, 0], [0, 0, 0]], dtype=np.int8),
        target=2,
        pattern=np.array([0, 1, 0, 0, 0, 0], dtype=bool),
        witness=np.array([0, -1, -1, -1, -1, -1]),
    )
    env = sb3_compatible(NeuronControlEnv(contexts=spikectl.ContextSet([context])))
    env.reset(seed=0)
    total = sum(env.step(from_env_action(int(a)))[1] for a in context.witness)
    assert total == pytest.approx(1.0, abs=1e-12)


def test_action_masks_mark_the_target_illegal():
    env = make()
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        target = env.env.unwrapped._observed_target
        expected = np.ones(9, dtype=bool)
        expected[target + 1] = False
        np.testing.assert_array_equal(env.action_masks(), expected)
        np.testing.assert_array_equal(info["action_mask"], expected)  # same indexing
    env = make(extensions={"allow_target_action": True})
    env.reset(seed=0)
    assert env.action_masks().all()


def test_illegal_action_does_nothing_by_default():
    env, reference = make(flatten=False), make(flatten=False)
    env.reset(seed=1)
    reference.reset(seed=1)
    illegal = int(np.flatnonzero(~env.action_masks())[0])
    for _ in range(4):
        obs, reward, _, _, info = env.step(illegal)
        ref_obs, ref_reward, _, _, ref_info = reference.step(DO_NOTHING)
        assert info["illegal_action"] and not ref_info["illegal_action"]
        assert reward == ref_reward and obs["last_action"] == DO_NOTHING
        np.testing.assert_array_equal(obs["voltage"], ref_obs["voltage"])


def test_illegal_action_raises_when_asked():
    env = make(illegal_action="raise")
    env.reset(seed=1)
    illegal = int(np.flatnonzero(~env.action_masks())[0])
    with pytest.raises(ValueError, match="target neuron"):
        env.step(illegal)


@pytest.mark.parametrize("action", [-1, 9, 1.5, "1"])
def test_actions_outside_the_space_raise(action):
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"not in Discrete\(9\)"):
        env.step(action)


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="illegal_action must be one of"):
        make(illegal_action="ignore")
    with pytest.raises(TypeError, match="wraps a spikectl NeuronControlEnv"):
        sb3_compatible(gym.make("CartPole-v1"))


def test_voltage_bounds_hand_computed():
    params = NeuronParams()
    # Stimulus +40 mV, synapse 20 mV, leak 1/20 per step, release every 5 steps at most.
    low, high = voltage_bounds_mV(params, 8)
    assert high == -50.0 + 40.0 + 8 * 20.0
    assert low == pytest.approx(-70.0 - 8 * 20.0 / (1 - 0.95**5), rel=1e-12)
    assert voltage_bounds_mV(params, 8, stochastic_release=True)[0] == pytest.approx(
        -70.0 - 8 * 20.0 / 0.05, rel=1e-12
    )
    never_releases = NeuronParams(release_scale=0.4)
    assert voltage_bounds_mV(never_releases, 8) == (-70.0, -10.0)


def test_paper_model_stays_inside_the_bounds():
    """Random play drives potentials far from rest; the bounds are never reached."""
    envs = NeuronControlVectorEnv(num_envs=64, **SMALL)
    low, high = voltage_bounds_mV(envs.params, envs.n_neurons)
    obs, infos = envs.reset(seed=0)
    lowest, highest = np.inf, -np.inf
    for _ in range(3 * envs.episode_length):
        obs, _, _, _, infos = envs.step(envs.action_space.sample())
        lowest, highest = min(lowest, obs["voltage"].min()), max(highest, obs["voltage"].max())
    assert low < lowest < -75.0 and -50.0 < highest < high


def test_noisy_observations_are_clipped_into_the_space():
    env = make(extensions={"observation_noise_mV": 1e4})
    obs, _ = env.reset(seed=0)
    k = 8
    saw_clipped = False
    for _ in range(10):
        assert obs in env.observation_space
        saw_clipped |= bool(np.isin(obs[:k], env.observation_space.low[:k]).any())
        obs, *_ = env.step(DO_NOTHING)
    assert saw_clipped


def test_flat_layout():
    env = make()
    obs, _ = env.reset(seed=0)
    base = env.env.unwrapped
    k, length, target = 8, 60, base._observed_target
    pattern = base._pattern.astype(np.float32)

    def parts(vector):
        cuts = np.cumsum([k, k, k + 1, length + 1, length])
        return np.split(vector, cuts)

    voltage, target_hot, last_hot, step_hot, pattern_part, ahead = parts(obs)
    np.testing.assert_array_equal(voltage, np.zeros(k))  # at rest: 0
    np.testing.assert_array_equal(target_hot, np.eye(k)[target])
    np.testing.assert_array_equal(last_hot, np.eye(k + 1)[0])
    np.testing.assert_array_equal(step_hot, np.eye(length + 1)[0])
    np.testing.assert_array_equal(pattern_part, pattern)
    np.testing.assert_array_equal(ahead, pattern)
    stimulated = (target + 1) % k
    obs, *_ = env.step(stimulated + 1)
    voltage, target_hot, last_hot, step_hot, pattern_part, ahead = parts(obs)
    # +40 mV with one step of leak from rest: (V - V_rest) / (V_th - V_rest) = 2.
    assert voltage[stimulated] == pytest.approx(2.0)
    np.testing.assert_array_equal(last_hot, np.eye(k + 1)[stimulated + 1])
    np.testing.assert_array_equal(step_hot, np.eye(length + 1)[1])
    np.testing.assert_array_equal(ahead, np.append(pattern[1:], -1.0))


@pytest.mark.parametrize("flatten", [True, False])
@pytest.mark.parametrize("env_id", [ENV_ID, "spikectl/NeuronControlPartial-v0"])
def test_gymnasium_check_env_is_silent(flatten, env_id):
    env = make(flatten, env_id=env_id, render_mode="ansi")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(env)


def test_spec_rebuilds_the_wrapped_environment():
    env = make(flatten=False, illegal_action="raise", episode_length=12)
    again = gym.make(env.spec)
    assert isinstance(again.unwrapped, SB3CompatibleEnv)
    assert again.unwrapped.illegal_action == "raise"
    assert again.observation_space == env.observation_space
    assert again.unwrapped.env.unwrapped.episode_length == 12


def test_renders_the_base_environment():
    env = make(render_mode="ansi")
    env.reset(seed=0)
    env.step(DO_NOTHING)
    assert env.render() == env.env.render() and env.render().startswith("step 1/60")


def test_seeded_episodes_repeat():
    a, b = make(), make()
    obs_a, _ = a.reset(seed=7)
    obs_b, _ = b.reset(seed=7)
    assert a.np_random is a.env.unwrapped.np_random  # one generator, the base env's
    assert a.np_random_seed == 7
    np.testing.assert_array_equal(obs_a, obs_b)
    for _ in range(30):
        action = a.action_space.sample()
        np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])


# -- with Stable-Baselines3 -------------------------------------------------------------------


@pytest.mark.parametrize("flatten", [True, False])
@pytest.mark.parametrize("env_id", [ENV_ID, "spikectl/NeuronControlRealistic-v0"])
def test_sb3_check_env_is_silent(flatten, env_id):
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = make(flatten, env_id=env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env_checker.check_env(env, warn=True)


def assert_same_observation(a, b, same_dtype=True):
    if isinstance(a, np.ndarray):
        a, b = {"": a}, {"": b}
    assert sorted(a) == sorted(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        assert not same_dtype or np.asarray(a[key]).dtype == np.asarray(b[key]).dtype, key


def legal_zero_based(rng, masks):
    return np.array([rng.choice(np.flatnonzero(mask)) for mask in masks])


@pytest.mark.parametrize("flatten", [True, False])
def test_vec_env_equals_dummy_vec_env_across_episodes(flatten):
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv

    num_envs, length = 3, 7
    batched = sb3_vec_env(
        gym.make_vec(ENV_ID, num_envs=num_envs, episode_length=length, **SMALL), flatten=flatten
    )
    dummy = DummyVecEnv([lambda: make(flatten, episode_length=length) for _ in range(num_envs)])
    for venv in (batched, dummy):
        venv.seed(5)
    obs_a, obs_b = batched.reset(), dummy.reset()
    rng = np.random.default_rng(0)
    dones_seen = 0
    for _ in range(3 * length + 2):
        masks = np.stack(batched.env_method("action_masks"))
        np.testing.assert_array_equal(masks, np.stack(dummy.env_method("action_masks")))
        actions = legal_zero_based(rng, masks)
        actions[0] = int(np.flatnonzero(~masks[0])[0])  # illegal: does nothing in both
        obs_a, rewards_a, dones_a, infos_a = batched.step(actions)
        obs_b, rewards_b, dones_b, infos_b = dummy.step(actions)
        assert_same_observation(obs_a, obs_b)
        np.testing.assert_array_equal(rewards_a, rewards_b)
        np.testing.assert_array_equal(dones_a, dones_b)
        for info_a, info_b in zip(infos_a, infos_b, strict=True):
            assert info_a["illegal_action"] == info_b["illegal_action"]
            assert info_a["context_index"] == info_b["context_index"]
            assert ("terminal_observation" in info_a) == ("terminal_observation" in info_b)
            if "terminal_observation" in info_a:
                # DummyVecEnv keeps the single env's Python ints: compare values.
                assert_same_observation(
                    info_a["terminal_observation"], info_b["terminal_observation"], False
                )
        dones_seen += int(dones_a.sum())
    assert dones_seen == 3 * num_envs
    for i in range(num_envs):
        row = {key: value[i] for key, value in obs_a.items()} if not flatten else obs_a[i]
        assert row in batched.observation_space


def test_vec_env_masks_reach_maskable_ppo_helpers_through_vec_wrappers():
    pytest.importorskip("stable_baselines3")
    utils = pytest.importorskip("sb3_contrib.common.maskable.utils")
    from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor, VecNormalize

    base = sb3_vec_env(gym.make_vec(ENV_ID, num_envs=4, **SMALL))
    venv = VecFrameStack(VecNormalize(VecMonitor(base)), n_stack=2)
    venv.seed(0)
    assert venv.reset().shape == (4, 2 * 206)
    assert utils.is_masking_supported(venv)
    masks = utils.get_action_masks(venv)
    inner = venv.unwrapped
    assert masks.shape == (4, 9) and masks.dtype == bool
    np.testing.assert_array_equal(masks, inner.action_masks())
    targets = inner.vector_env._observed_targets
    np.testing.assert_array_equal(
        np.flatnonzero(~masks.reshape(-1)), np.arange(4) * 9 + targets + 1
    )


def test_vec_env_errors_are_one_line():
    pytest.importorskip("stable_baselines3")
    venv = sb3_vec_env(gym.make_vec(ENV_ID, num_envs=2, **SMALL), illegal_action="raise")
    venv.reset()
    with pytest.raises(ValueError, match=r"actions must be integers in 0\.\.8"):
        venv.step(np.array([0, 9]))
    illegal = int(np.flatnonzero(~venv.action_masks()[1])[0])
    with pytest.raises(ValueError, match="env 1: action .* stimulates the target"):
        venv.step(np.array([0, illegal]))
    with pytest.raises(AttributeError, match="no per-environment method 'render'"):
        venv.env_method("render")
    with pytest.raises(TypeError, match="wraps a spikectl NeuronControlVectorEnv"):
        sb3_vec_env(gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync"))


def test_vec_env_reset_options_choose_contexts():
    pytest.importorskip("stable_baselines3")
    venv = sb3_vec_env(gym.make_vec(ENV_ID, num_envs=3, **SMALL))
    venv.set_options([{"context": 4}, {"context": 2}, {"context": 9}])
    venv.reset()
    assert [info["context_index"] for info in venv.reset_infos] == [4, 2, 9]
    venv.set_options({"speed": 1})
    with pytest.raises(ValueError, match="the only reset option is 'context'"):
        venv.reset()


def test_sb3_vec_env_without_sb3_says_what_to_install(monkeypatch):
    for name in [name for name in sys.modules if name.startswith("stable_baselines3")]:
        monkeypatch.setitem(sys.modules, name, None)  # as if it were not installed
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    monkeypatch.delitem(sys.modules, "spikectl.wrappers.sb3_vec_adapter", raising=False)
    with pytest.raises(ImportError, match=r'pip install "spikectl\[sb3\]"'):
        sb3_vec_env(gym.make_vec(ENV_ID, num_envs=2, **SMALL))


# -- MaskablePPO (slow) -------------------------------------------------------------------


def one_easy_context(episode_length: int = 6):
    """Three neurons, one excitatory edge 0 -> 2, target 2, wanted spike at step 1:
    stimulating neuron 0 at step 0 (action 1) scores 1, doing nothing 0.5."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = 1
    pattern = np.zeros(episode_length, dtype=bool)
    pattern[1] = True
    witness = np.full(episode_length, -1)
    witness[0] = 0
    return spikectl.ContextSet([make_context(weights, 2, pattern, witness)])


@pytest.fixture
def one_torch_thread():
    """One Torch thread: on a busy machine two threads slow PPO down many times over."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.mark.slow
def test_maskable_ppo_learns_an_easy_network_and_predicts_legal_actions(one_torch_thread):
    pytest.importorskip("stable_baselines3")
    sb3_contrib = pytest.importorskip("sb3_contrib")

    easy = one_easy_context()
    venv = sb3_vec_env(NeuronControlVectorEnv(num_envs=4, contexts=easy))
    model = sb3_contrib.MaskablePPO(
        "MlpPolicy", venv, n_steps=48, batch_size=48, seed=0, device="cpu"
    )
    model.learn(4000)
    env = sb3_compatible(NeuronControlEnv(contexts=easy))
    obs, _ = env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
        obs, reward, done, _, info = env.step(action)
        total += reward
    assert total == pytest.approx(1.0, abs=1e-12)  # do nothing: 0.5

    # On the paper's networks (n = 8, N = 60): a short run, then only legal predictions.
    venv = sb3_vec_env(gym.make_vec(ENV_ID, num_envs=4, **SMALL))
    model = sb3_contrib.MaskablePPO("MlpPolicy", venv, n_steps=60, seed=0, device="cpu")
    model.learn(480)
    env = make()
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            action, _ = model.predict(obs, action_masks=env.action_masks())
            obs, _, done, _, info = env.step(action)
            assert not info["illegal_action"]
