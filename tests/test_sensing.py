"""Spikes-only sensing (``Extensions(sensing="spikes")``, docs/extensions.md): the
observation's ``spikes`` replaces its ``voltage``; everything else is the paper's. Cleo's
agreement is in tests/test_bridge_cleo.py."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from spikectl.cli import main
from spikectl.config_errors import ConfigError
from spikectl.contexts import Context, ContextSet
from spikectl.envs.controller import ControllerInputError, RandomLegal
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.env_support import observation_space
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.envs.registration import flat_id
from spikectl.envs.rollout import evaluate_policy
from spikectl.envs.sensing import SPIKES_KEY
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning import IdentifyAndPlan, named_composition
from spikectl.planning.oracle import OraclePlanner
from spikectl.wrappers.flat_env import FlatEnv, FlatNeuronControlEnv

SPIKES = {"sensing": "spikes"}
SHORT = {"contexts": {"n_train": 6, "n_test": 2}, "episode_length": 12}
LENGTH = 6


def chain() -> ContextSet:
    """Neuron 0 excites neuron 1 (the target); neuron 2 is unconnected. Stimulated at rest,
    neuron 0 spikes at once (-70 + 40 = -30 mV) and neuron 1 one step later (-70 + 20 =
    -50 mV, the threshold). The pattern wants one spike, at step 1."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 1] = 1
    pattern = np.zeros(LENGTH, dtype=bool)
    pattern[1] = True
    return ContextSet([Context(weights, 1, pattern)], NeuronParams())


def random_episode(env, seed: int, episodes: int = 2):
    """(observations, rewards) of ``episodes`` random episodes (actions seeded alike; a
    flat environment's are zero-based)."""
    rng = np.random.default_rng(seed)
    flat = isinstance(env, FlatEnv)
    observation, info = env.reset(seed=seed)
    observations, rewards = [observation], []
    for _ in range(episodes):
        for _ in range((env.env if flat else env).unwrapped.episode_length):
            action = int(rng.choice(np.flatnonzero(info["action_mask"]))) - (not flat)
            observation, reward, terminated, _, info = env.step(action)
            observations.append(observation)
            rewards.append(reward)
        observation, info = env.reset()
        observations.append(observation)
    return observations, rewards


# -- the hand-computed chain


def test_the_chain_shows_each_spike_at_the_step_after_it():
    env = NeuronControlEnv(contexts=chain(), extensions=SPIKES)
    observation, _ = env.reset(seed=0)
    assert "voltage" not in observation and observation[SPIKES_KEY].dtype == np.int8
    assert observation[SPIKES_KEY].tolist() == [0, 0, 0]  # nothing has spiked yet
    seen, rewards = [], []
    for action in (0, DO_NOTHING, 2, DO_NOTHING, DO_NOTHING, DO_NOTHING):
        observation, reward, *_ = env.step(action)
        seen.append(observation[SPIKES_KEY].tolist())
        rewards.append(reward)
    assert seen == [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
    # One wanted spike (0.5) and five silences (0.5 / 5 each): the target spiked at step 1.
    np.testing.assert_allclose(rewards, [0.1, 0.5, 0.1, 0.1, 0.1, 0.1])
    assert observation["last_action"] == DO_NOTHING and observation["step"] == LENGTH


# -- off is the paper; on sees a function of what the paper's agent sees


def test_the_default_is_the_paper():
    assert Extensions(sensing="potentials") == Extensions()
    assert "sensing" not in Extensions().to_dict(only_changed=True)
    plain = NeuronControlEnv(**SHORT)
    explicit = NeuronControlEnv(**SHORT, extensions={"sensing": "potentials"})
    assert explicit.observation_space == plain.observation_space == observation_space(8, 12)
    a, ra = random_episode(plain, 3)
    b, rb = random_episode(explicit, 3)
    assert ra == rb
    for x, y in zip(a, b, strict=True):
        assert list(x) == list(y) and all(np.array_equal(x[key], y[key]) for key in x)


@pytest.mark.parametrize(
    "extensions",
    [{}, {"hidden_fraction": 0.25, "latency_steps": 2}, {"stochastic_release": True,
                                                          "background_rate": 0.05}],
)  # fmt: skip
def test_spikes_are_the_papers_potentials_at_threshold(extensions):
    """Same seeds, same actions: the spikes-only episode is the paper's, its spikes the
    paper's observed potentials >= V_th, every other key and every reward equal."""
    paper = NeuronControlEnv(**SHORT, extensions=extensions)
    spiking = NeuronControlEnv(**SHORT, extensions={**extensions, **SPIKES})
    a, ra = random_episode(paper, 5, episodes=3)
    b, rb = random_episode(spiking, 5, episodes=3)
    assert ra == rb
    threshold = NeuronParams().v_threshold_mV
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(y[SPIKES_KEY], (x["voltage"] >= threshold).astype(np.int8))
        assert set(x) - {"voltage"} == set(y) - {SPIKES_KEY}
        for key in set(x) - {"voltage"}:
            np.testing.assert_array_equal(x[key], y[key])


def test_the_space_holds_every_observation_and_the_env_checker_passes():
    env = NeuronControlEnv(**SHORT, extensions={**SPIKES, "latency_steps": 1})
    space = env.observation_space
    assert set(space.spaces) == {SPIKES_KEY, "target", "pattern", "step", "last_action",
                                 IN_FLIGHT_KEY}  # fmt: skip
    assert space[SPIKES_KEY] == gym.spaces.MultiBinary(8)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*infinity.*")
        check_env(env, skip_render_check=True)
    observations, _ = random_episode(env, 2)
    assert all(observation in space for observation in observations)


def test_an_episode_pickled_mid_way_continues_identically():
    env = NeuronControlEnv(**SHORT, extensions=SPIKES)
    env.reset(seed=5)
    for action in (0, 3, 4):
        env.step(action if env.action_space.legal_mask[action + 1] else DO_NOTHING)
    copy = pickle.loads(pickle.dumps(env))
    for action in (1, 2, DO_NOTHING):
        action = action if env.action_space.legal_mask[action + 1] else DO_NOTHING
        a, ra, *_ = env.step(action)
        b, rb, *_ = copy.step(action)
        assert ra == rb and all(np.array_equal(a[key], b[key]) for key in a)


# -- the vector environment


def test_evaluate_policy_gives_the_papers_returns():
    """A controller that does not read the potentials scores the same either way; the
    episodes' potentials are the spikes as an agent reads them (tests/test_spikes_learners.py)."""
    test_set = ContextSet.generate(6, n_neurons=8, seed=3)
    paper = evaluate_policy(test_set, RandomLegal(seed=1))
    spiking = evaluate_policy(test_set, RandomLegal(seed=1), extensions=Extensions(**SPIKES))
    np.testing.assert_array_equal(paper.rewards, spiking.rewards)
    np.testing.assert_array_equal(paper.spikes, spiking.spikes)
    assert set(np.unique(spiking.voltage)) == {-70.0, -50.0}  # V_r, and V_th at a spike


# -- the flat wrappers


def test_the_flat_layout_holds_the_spikes_in_the_voltage_columns():
    """The paper's 3k + 3N + 2 entries: the first k are the spikes (bounds 0 and 1), the
    rest equal the paper's flat observation's; the Dict form has int8 ``spikes``."""
    paper, flat = FlatNeuronControlEnv(**SHORT), FlatNeuronControlEnv(**SHORT, extensions=SPIKES)
    k = 8
    assert flat.observation_space.shape == paper.observation_space.shape == (3 * k + 3 * 12 + 2,)
    np.testing.assert_array_equal(flat.observation_space.low[:k], 0.0)
    np.testing.assert_array_equal(flat.observation_space.high[:k], 1.0)
    np.testing.assert_array_equal(flat.observation_space.low[k:], paper.observation_space.low[k:])
    a, ra = random_episode(paper, 4)
    b, rb = random_episode(flat, 4)
    assert ra == rb
    for x, y in zip(a, b, strict=True):
        assert y in flat.observation_space
        np.testing.assert_array_equal(y[k:], x[k:])
        # The paper's columns are (V - V_r) / (V_th - V_r): a spike reads >= 1.
        np.testing.assert_array_equal(y[:k], (x[:k] >= 1.0).astype(np.float32))
    assert any(y[:k].any() for y in b)  # spikes were compared, not only zeros
    as_dict = FlatEnv(NeuronControlEnv(**SHORT, extensions=SPIKES), flatten=False)
    observation, _ = as_dict.reset(seed=0)
    assert as_dict.observation_space[SPIKES_KEY] == gym.spaces.MultiBinary(8)
    assert "voltage" not in as_dict.observation_space.spaces
    assert observation in as_dict.observation_space


def test_the_ids_are_registered_with_a_flat_twin():
    env_id = "spikectl/NeuronControlSpikesOnly-v0"
    env = gym.make(env_id, contexts={"n_train": 4, "n_test": 4})
    assert env.unwrapped.extensions == Extensions(**SPIKES)
    assert SPIKES_KEY in env.observation_space.spaces
    flat = gym.make(flat_id(env_id), contexts={"n_train": 4, "n_test": 4})
    assert flat.observation_space.shape == (3 * 8 + 3 * 60 + 2,)
    vector = gym.make_vec(env_id, num_envs=2, contexts={"n_train": 4, "n_test": 4})
    assert vector.unwrapped.extensions.spikes_only


# -- bad settings and who cannot play it


@pytest.mark.parametrize("value", ["volts", "Spikes", 1, None, True])
def test_a_bad_sensing_is_one_named_line(value):
    with pytest.raises(ConfigError, match=r"Extensions\.sensing must be one of") as error:
        Extensions(sensing=value)
    assert "\n" not in str(error.value)
    with pytest.raises(ConfigError, match="sensing"):
        NeuronControlEnv(**SHORT, extensions={"sensing": value})


@pytest.mark.parametrize("other", [{"observation_noise_mV": 1.0},
                                   {"bleaching_time_constant_steps": 100.0}])  # fmt: skip
def test_transforms_of_unobserved_potentials_are_refused(other):
    with pytest.raises(ConfigError, match="observes no potentials") as error:
        Extensions(**SPIKES, **other)
    assert "\n" not in str(error.value)


def test_the_cli_refuses_a_bad_sensing(tmp_path, capsys):
    """(Training on spikes: tests/test_spikes_learners.py.)"""
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "smoke", "--extensions.sensing", "volts", "--total-env-steps", "320",
              "--run-dir", str(tmp_path / "volts")])  # fmt: skip
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert "must be one of 'potentials', 'spikes'" in error and len(error.splitlines()) == 1
    assert not (tmp_path / "volts").exists()


def test_the_oracle_plays_as_in_the_papers_setting_and_identify_and_plan_reads_spikes():
    """The oracle knows the network and plans open loop: the same actions, the same
    returns. identify-and-plan built for potentials refuses spikes in one line; built
    for the environment it plays them (tests/test_spike_filter.py)."""
    test_set = ContextSet.generate(4, n_neurons=8, seed=11)
    paper = evaluate_policy(test_set, OraclePlanner(test_set))
    spiking = evaluate_policy(test_set, OraclePlanner(test_set),
                              extensions=Extensions(**SPIKES))  # fmt: skip
    np.testing.assert_array_equal(paper.actions, spiking.actions)
    np.testing.assert_array_equal(paper.rewards, spiking.rewards)
    env = NeuronControlEnv(contexts=test_set, extensions=SPIKES)
    observation, info = env.reset(seed=0)
    with pytest.raises(ControllerInputError, match="observes 'voltage'"):
        IdentifyAndPlan(test_set.params).act(observation, info)
    spikes = Extensions(**SPIKES)
    playing = IdentifyAndPlan(test_set.params, named_composition(spikes, 8), extensions=spikes)
    assert playing.act(observation, info) in np.flatnonzero(info["action_mask"]) - 1
