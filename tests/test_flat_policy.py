"""FlatPolicyController: a policy trained on a flat id plays the suite's networks exactly as
it played the flat id (same observations, same actions, same returns), through every
entry point that plays controllers; bad policy outputs raise FlatPolicyError."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import spikectl  # noqa: F401  (registers the ids)
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.wrappers import FlatPolicyController, FlatPolicyError

FLAT_ID = "spikectl/NeuronControlFlat-v0"


def linear_policy(size: int, seed: int = 0):
    """A fixed linear scorer of the flat observation: its actions depend on every entry."""
    weights = np.random.default_rng(seed).normal(size=(size, 9)).astype(np.float32)
    return lambda observations, mask: (observations @ weights).argmax(axis=1)


def play_flat(env_id: str, policy, num_envs: int, seed: int):
    envs = gym.make_vec(env_id, num_envs=num_envs, split="test")
    observations, infos = envs.reset(seed=seed)
    actions, returns = [], np.zeros(num_envs)
    for _ in range(envs.unwrapped.episode_length):
        action = policy(observations, infos["action_mask"])
        legal = infos["action_mask"][np.arange(num_envs), action] == 1
        actions.append(np.where(legal, action, 0))  # what the flat env did: nothing if illegal
        observations, rewards, _, _, infos = envs.step(action)
        returns += rewards
    return np.array(actions), returns


@pytest.mark.parametrize("env_id", [FLAT_ID, "spikectl/NeuronControlNoisyFlat-v0"])
def test_the_controller_on_the_paper_env_acts_as_the_policy_on_the_flat_id(env_id):
    policy = linear_policy(206)
    flat_actions, flat_returns = play_flat(env_id, policy, num_envs=6, seed=3)
    assert len(set(flat_actions.reshape(-1).tolist())) > 3  # the test sees many actions

    controller = FlatPolicyController.for_env(policy, gym.make(env_id))
    paper = gym.make_vec(env_id.replace("Flat", ""), num_envs=6, split="test")
    observations, infos = paper.reset(seed=3)
    actions, returns = [], np.zeros(6)
    for _ in range(paper.unwrapped.episode_length):
        action = controller.act_batch(observations, infos)
        actions.append(action + 1)  # the paper's -1..n-1 as the flat 0..n
        observations, rewards, _, _, infos = paper.step(action)
        returns += rewards
    np.testing.assert_array_equal(np.array(actions), flat_actions)
    np.testing.assert_array_equal(returns, flat_returns)


def test_one_environment_acts_as_its_row_of_the_batch():
    controller = FlatPolicyController.for_env(linear_policy(206, seed=1), gym.make(FLAT_ID))
    envs = gym.make_vec("spikectl/NeuronControl-v0", num_envs=3)
    observations, infos = envs.reset(seed=0)
    batch = controller.act_batch(observations, infos)
    for i in range(3):
        one = {key: value[i] for key, value in observations.items()}
        assert controller.act(one, {"action_mask": infos["action_mask"][i]}) == batch[i]


def test_the_suite_scores_it_and_resets_it_once_per_set():
    resets = []
    policy = linear_policy(206, seed=2)
    controller = FlatPolicyController.for_env(policy, gym.make(FLAT_ID), lambda: resets.append(1))
    score = suite.score("paper", "test", lambda seed: controller)
    played = evaluate_policy(
        suite.load_split("paper", "test"), controller, seed=suite.suite_version(1).env_seed
    )
    assert len(resets) == 2  # one batched episode on every network, each time
    np.testing.assert_array_equal(score.returns, played.returns)
    assert 0.3 < score.mean_return < 0.7


def test_an_illegal_action_does_nothing_as_on_the_flat_id():
    envs = gym.make_vec("spikectl/NeuronControl-v0", num_envs=4)
    observations, infos = envs.reset(seed=0)
    target = observations["target"]  # the target neuron's flat action is target + 1
    controller = FlatPolicyController.for_env(lambda o, m: target + 1, envs)
    np.testing.assert_array_equal(controller.act_batch(observations, infos), [-1] * 4)


@pytest.mark.parametrize(
    ("returned", "message"),
    [
        (lambda o, m: np.zeros(len(o) + 1, dtype=int), "returned 5 actions for 4 observations"),
        (lambda o, m: np.zeros(len(o)), "float64 actions, not integers"),
        (lambda o, m: np.full(len(o), 9), "outside 0..8"),
        (lambda o, m: np.full(len(o), -1), "outside 0..8"),
    ],
)
def test_a_policy_that_returns_what_no_flat_env_accepts_is_named(returned, message):
    envs = gym.make_vec("spikectl/NeuronControl-v0", num_envs=4)
    observations, infos = envs.reset(seed=0)
    controller = FlatPolicyController.for_env(returned, envs)
    with pytest.raises(FlatPolicyError, match=message):
        controller.act_batch(observations, infos)


def test_torch_actions_are_taken():
    torch = pytest.importorskip("torch")
    envs = gym.make_vec("spikectl/NeuronControl-v0", num_envs=2)
    observations, infos = envs.reset(seed=0)
    controller = FlatPolicyController.for_env(
        lambda o, m: torch.zeros(len(o), dtype=torch.long), envs
    )
    np.testing.assert_array_equal(controller.act_batch(observations, infos), [-1, -1])


def test_a_policy_that_is_not_callable_is_refused():
    with pytest.raises(TypeError, match="policy must be callable"):
        FlatPolicyController.for_env("not a policy", gym.make(FLAT_ID))


def test_the_n16_id_trains_on_the_suite_task_n16():
    from spikectl.experiments.suite.protocol import suite_checksum

    env = gym.make("spikectl/NeuronControl16Flat-v0")
    assert env.observation_space.shape == (3 * 16 + 3 * 60 + 2,)
    expected = suite.task("n16").checksums["train"]
    assert suite_checksum(env.unwrapped.env.unwrapped.contexts) == expected
