"""NeuronControlEnv: Gymnasium API, rewards, actions, observations, seeding, pickling."""

from __future__ import annotations

import copy
import importlib
import math
import pickle
import re
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env

import spikectl
from spikectl.contexts import ContextSet, make_context, make_splits
from spikectl.envs import registration
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.env_support import MAX_REWARD, step_rewards
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.params import NeuronParams

ENV_ID = registration.ENV_ID
SMALL = {"contexts": {"n_train": 10, "n_test": 10}}
# Gymnasium's checker warns about any unbounded Box; the voltage is unbounded by design
# (docs/environment.md).
UNBOUNDED_BOX = re.compile(r"Box observation space (minimum|maximum) value is -?infinity")


def tiny_context(episode_length: int = 6):
    """Three neurons, one excitatory edge 0 -> 2, target 2: stimulating 0 fires 2 a step later."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = 1
    witness = np.full(episode_length, -1)
    witness[0] = 0
    pattern = np.zeros(episode_length, dtype=bool)
    pattern[1] = True
    return make_context(weights, target=2, pattern=pattern, witness=witness)


def tiny_env(**kwargs) -> NeuronControlEnv:
    return NeuronControlEnv(contexts=ContextSet([tiny_context()]), **kwargs)


def legal_action(rng: np.random.Generator, mask: np.ndarray) -> int:
    return int(rng.choice(np.flatnonzero(mask))) - 1


def run_episode(env, rng, reset_kwargs):
    obs, info = env.reset(**reset_kwargs)
    trajectory = [(obs, info)]
    terminated = False
    while not terminated:
        obs, reward, terminated, truncated, info = env.step(legal_action(rng, info["action_mask"]))
        assert truncated is False
        trajectory.append((obs, reward, terminated, info))
    return trajectory


def assert_same(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    else:
        assert type(a) is type(b) and a == b


def episode_return(env, actions, context) -> float:
    env.reset(options={"context": context})
    total = 0.0
    for t, action in enumerate(actions):
        _, reward, terminated, _, _ = env.step(int(action))
        total += reward
        assert terminated == (t == len(actions) - 1)
    return total


@pytest.mark.parametrize("through_make", [False, True])
def test_check_env_passes(through_make):
    if through_make:  # the checker then also tries every render mode through the spec
        env = gym.make(ENV_ID, **SMALL)
        expected = UNBOUNDED_BOX
    else:
        env = NeuronControlEnv(render_mode="rgb_array", **SMALL)
        expected = re.compile(f"{UNBOUNDED_BOX.pattern}|environment not having a spec")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught if not expected.search(str(w.message))] == []


def test_make_builds_the_env_with_its_kwargs():
    env = gym.make(ENV_ID, n_neurons=6, episode_length=20, **SMALL)
    assert isinstance(env.unwrapped, NeuronControlEnv)
    assert (env.unwrapped.n_neurons, env.unwrapped.episode_length) == (6, 20)
    assert env.unwrapped.contexts == make_splits(10, 10, 6, 20, seed=0)[0]


def test_registration_is_idempotent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        registration.register_envs()
        importlib.reload(registration).register_envs()
        importlib.reload(spikectl)
    spec = gym.spec(ENV_ID)
    assert spec.entry_point == "spikectl.envs.env:NeuronControlEnv"
    assert spec.vector_entry_point == "spikectl.envs.vector_env:NeuronControlVectorEnv"


def test_same_seed_same_episodes():
    env_a, env_b = NeuronControlEnv(**SMALL), NeuronControlEnv(**SMALL)
    for episode in range(3):
        kwargs = {"seed": 7} if episode == 0 else {}
        a = run_episode(env_a, np.random.default_rng(episode), kwargs)
        b = run_episode(env_b, np.random.default_rng(episode), kwargs)
        assert_same(a, b)


def test_different_seeds_choose_different_contexts():
    def contexts_drawn(seed):
        env = NeuronControlEnv(**SMALL)
        indices = [env.reset(seed=seed)[1]["context_index"]]
        indices += [env.reset()[1]["context_index"] for _ in range(7)]
        return indices

    assert contexts_drawn(1) == contexts_drawn(1)
    assert contexts_drawn(1) != contexts_drawn(2)


def test_pickled_env_continues_identically():
    env = NeuronControlEnv(**SMALL)
    rng = np.random.default_rng(0)
    _, info = env.reset(seed=3)
    for _ in range(25):
        _, _, _, _, info = env.step(legal_action(rng, info["action_mask"]))
    clones = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    for _ in range(2):  # the rest of this episode, then a whole new one
        terminated = False
        while not terminated:
            action = legal_action(rng, info["action_mask"])
            result = env.step(action)
            for clone in clones:
                assert_same(clone.step(action), result)
            terminated, info = result[2], result[4]
        reset = env.reset()
        for clone in clones:
            assert_same(clone.reset(), reset)
        _, info = reset


@pytest.mark.parametrize(("n_neurons", "episode_length", "size"), [(8, 60, 30), (12, 40, 15)])
def test_do_nothing_scores_half_and_the_witness_scores_one(n_neurons, episode_length, size):
    train, _ = make_splits(size, 1, n_neurons, episode_length, seed=5)
    env = NeuronControlEnv(contexts=train)
    nothing = np.full(episode_length, -1)
    for index, context in enumerate(train):
        assert math.isclose(episode_return(env, nothing, index), 0.5, rel_tol=0, abs_tol=1e-12)
        assert math.isclose(
            episode_return(env, context.witness, index), 1.0, rel_tol=0, abs_tol=1e-12
        )


def test_rewards_by_hand_on_a_tiny_context():
    env = tiny_env()
    silence = MAX_REWARD / 5  # pattern [0, 1, 0, 0, 0, 0]: m = 1 spike, N - m = 5 silences

    def rewards(actions):
        env.reset(options={"context": 0})
        return [env.step(a)[1] for a in actions]

    assert rewards([0, -1, -1, -1, -1, -1]) == [silence, 0.5, silence, silence, silence, silence]
    assert rewards([1] * 6) == [silence, 0.0, silence, silence, silence, silence]
    # Stimulating too late: the target misses step 1 and spikes unwanted at step 2.
    assert rewards([-1, 0, -1, -1, -1, -1]) == [silence, 0.0, 0.0, silence, silence, silence]
    # A second spike of neuron 0 within 5 steps of its release releases nothing (depression).
    assert rewards([0, -1, -1, 0, -1, -1]) == [silence, 0.5, silence, silence, silence, silence]


def test_step_rewards_formula():
    reward_if_spike, reward_if_silent = step_rewards(np.array([[1, 0, 0, 1, 0]]))
    np.testing.assert_array_equal(reward_if_spike, [[0.25, 0, 0, 0.25, 0]])
    np.testing.assert_array_equal(reward_if_silent, [[0, 0.5 / 3, 0.5 / 3, 0, 0.5 / 3]])
    with pytest.raises(ValueError, match="at least one spike"):
        step_rewards(np.zeros((1, 4)))


def test_observations_and_infos():
    env = tiny_env()
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(obs["voltage"], np.full(3, -70.0, dtype=np.float32))
    assert obs["voltage"].dtype == np.float32
    assert (obs["target"], obs["step"], obs["last_action"]) == (2, 0, -1)
    np.testing.assert_array_equal(obs["pattern"], [0, 1, 0, 0, 0, 0])
    assert obs["pattern"].dtype == np.int8
    np.testing.assert_array_equal(info["action_mask"], [True, True, True, False])
    assert info["context_index"] == 0

    obs, reward, terminated, truncated, info = env.step(np.int32(0))
    assert obs["voltage"][0] == -30.0  # -70 mV + 40 mV of stimulus, observed before the reset
    assert obs["voltage"][2] == -70.0
    assert (obs["step"], obs["last_action"]) == (1, 0)
    np.testing.assert_array_equal(info["spikes"], [True, False, False])
    assert info["target_spiked"] is False
    obs, reward, terminated, truncated, info = env.step(np.array(-1))
    assert obs["voltage"][2] == -50.0 and info["target_spiked"] is True and reward == 0.5
    assert obs["voltage"][0] == -70.0  # refractory: held at rest
    assert (obs["step"], obs["last_action"]) == (2, -1)
    for _ in range(4):
        obs, _, terminated, truncated, _ = env.step(-1)
    assert (obs["step"], terminated, truncated) == (6, True, False)
    assert obs in env.observation_space


def test_mutating_returned_data_does_not_change_the_env():
    env = tiny_env()
    obs, info = env.reset()
    info["action_mask"][:] = True
    obs["pattern"][:] = 0
    with pytest.raises(ValueError, match="target neuron 2"):
        env.step(2)
    assert env.step(-1)[0]["pattern"][1] == 1


def test_illegal_actions_raise_with_a_clear_message():
    env = tiny_env()
    env.reset()
    with pytest.raises(ValueError, match=r"action 2 stimulates the target neuron 2"):
        env.step(2)
    for action in (3, -2, np.int64(7)):
        with pytest.raises(ValueError, match=rf"action {action} is out of range.*target 2"):
            env.step(action)
    for action in (1.0, np.float64(0), "0", None, True, np.array([0])):
        with pytest.raises(ValueError, match="action must be an integer"):
            env.step(action)
    assert env.unwrapped._next_step == 0  # nothing was simulated
    env.step(np.array(1, dtype=np.int16))


def test_allow_target_action_makes_the_target_legal():
    env = tiny_env(extensions={"allow_target_action": True})
    _, info = env.reset()
    assert info["action_mask"].all()
    _, _, _, _, info = env.step(2)
    assert info["target_spiked"] is True


def test_action_space_samples_only_legal_actions():
    env = NeuronControlEnv(**SMALL)
    env.action_space.seed(0)
    for seed in range(20):
        _, info = env.reset(seed=seed)
        samples = {int(env.action_space.sample()) for _ in range(50)}
        assert all(info["action_mask"][a + 1] for a in samples)
        assert env.action_space == gym.spaces.Discrete(9, start=-1)


def test_stepping_outside_an_episode_raises():
    env = tiny_env()
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(-1)
    env.reset()
    for _ in range(6):
        env.step(-1)
    with pytest.raises(ResetNeeded, match="terminated"):
        env.step(-1)


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"split": "validation"}, ValueError, "split"),
        ({"render_mode": "human"}, ValueError, "render_mode"),
        ({"n_neurons": 1}, ValueError, "n_neurons"),
        ({"episode_length": 1}, ValueError, "episode_length"),
        ({"contexts": {"n_train": 0}}, ValueError, "contexts: n_train"),
        ({"contexts": {"n_test": 2.5}}, ValueError, "contexts: n_test"),
        ({"contexts": {"seed": -1}}, ValueError, "contexts: seed"),
        ({"contexts": {"context_seed": 1}}, ValueError,
         r"contexts: unknown key\(s\) \['context_seed'\]; generated sets take n_train, "
         "n_test, seed"),
        ({"n_train": 10}, TypeError, "unexpected keyword argument 'n_train'"),
        ({"allow_target_action": True}, TypeError, "unexpected keyword argument"),
        ({"contexts": 42}, TypeError, "contexts"),
        ({"params": {"dt_ms": 1.0}}, TypeError, "params"),
        ({"extensions": {"allow_target_action": "yes"}}, TypeError, "allow_target_action"),
    ],
)
def test_bad_constructor_arguments(kwargs, error, message):
    with pytest.raises(error, match=message):
        NeuronControlEnv(**SMALL | kwargs)


def test_sizes_come_from_a_given_context_set():
    contexts = ContextSet([tiny_context()])
    env = NeuronControlEnv(contexts=contexts, n_neurons=3)
    assert (env.n_neurons, env.episode_length) == (3, 6)
    with pytest.raises(ValueError, match="n_neurons=8 conflicts"):
        NeuronControlEnv(contexts=contexts, n_neurons=8)
    with pytest.raises(ValueError, match="episode_length=60 conflicts"):
        NeuronControlEnv(contexts=contexts, episode_length=60)


def test_the_environment_plays_its_contexts_params():
    """One route: params= generates contexts; beside contexts only theirs are taken."""
    params = NeuronParams(release_scale=0.8)
    train, _ = make_splits(3, 1, seed=0, params=params)
    assert NeuronControlEnv(contexts=train).params == params
    assert NeuronControlEnv(contexts={"n_train": 3, "n_test": 1}, params=params).contexts == train
    assert NeuronControlEnv(contexts=train, params=params).params == params
    for make in (NeuronControlEnv, NeuronControlVectorEnv):
        with pytest.raises(ValueError, match=r"params: params= differ from those the contexts "
                           r"were made with: release_scale 0.65 \(theirs: 0.8\); the "
                           "environment plays the contexts' own"):  # fmt: skip
            make(contexts=train, params=NeuronParams())


def test_reset_options():
    env = NeuronControlEnv(**SMALL)
    own = make_splits(1, 1, seed=99)[0][0]
    obs, info = env.reset(options={"context": own})
    assert info["context_index"] is None and obs["target"] == own.target
    np.testing.assert_array_equal(obs["pattern"], own.pattern)
    assert env.reset(options={"context": np.int64(4)})[1]["context_index"] == 4
    with pytest.raises(ValueError, match="3 neurons and episode length 6"):
        env.reset(options={"context": tiny_context()})
    for bad in (10, -1, 1.0, True):
        with pytest.raises(ValueError, match=r"context index must be an integer in 0\.\.9"):
            env.reset(options={"context": bad})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"contxt": 1})


def test_contexts_load_from_a_saved_file(tmp_path: Path):
    train, _ = make_splits(4, 2, n_neurons=5, episode_length=12, seed=1)
    path = train.save(tmp_path / "train.npz")
    for given in (path, str(path)):
        env = NeuronControlEnv(contexts=given)
        assert env.contexts == train and env.n_neurons == 5
        env.reset(seed=0)
        env.step(-1)


def test_documented_example_runs():
    text = (Path(__file__).parents[1] / "docs" / "environment.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.DOTALL)
    assert blocks
    for block in blocks:
        exec(compile(block, "docs/environment.md", "exec"), {})


def test_random_legal_actions_uniform_over_legal_and_seeded():
    from spikectl.envs.env_support import random_legal_actions

    mask = np.array([[True, False, True, True], [False, False, False, False]])  # [2, n + 1]
    draws = random_legal_actions(np.repeat(mask[:1], 30_000, axis=0), np.random.default_rng(0))
    values, counts = np.unique(draws, return_counts=True)
    assert values.tolist() == [-1, 1, 2]  # never action 0, the illegal one
    assert np.all(np.abs(counts / 30_000 - 1 / 3) < 0.01)
    assert random_legal_actions(mask, np.random.default_rng(0))[1] == -1  # nothing legal
    first, second = (random_legal_actions(mask, np.random.default_rng(7)) for _ in range(2))
    assert first.dtype == np.int64 and first.tolist() == second.tolist()
