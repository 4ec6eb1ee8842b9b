"""Loop latency (``Extensions.latency_steps``, docs/extensions.md): an action chosen at step t
stimulates at step t + L; the observation carries the actions in flight; the oracle plans
for the loop it plays. Cleo's agreement is in tests/test_bridge_cleo.py."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_flat_vector_env_steps_as_singles, step_alike
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from spikectl.config_errors import ConfigError
from spikectl.contexts import Context, ContextSet
from spikectl.envs.controller import DoNothing, play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.env_support import observation_space
from spikectl.envs.latency import IN_FLIGHT_KEY, ActionDelay
from spikectl.envs.registration import flat_id, registered_kwargs
from spikectl.envs.rollout import evaluate_policy
from spikectl.envs.sensing import SPIKES_KEY
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning.oracle import OraclePlanner, plan_episode
from spikectl.wrappers.flat_env import FlatNeuronControlEnv
from spikectl.wrappers.flat_vector_env import FlatNeuronControlVectorEnv

SHORT = {"contexts": {"n_train": 6, "n_test": 2}, "episode_length": 12}
LENGTH = 6


def chain(pattern_step: int = 3) -> ContextSet:
    """Neuron 0 excites neuron 1 (the target); neuron 2 is unconnected. Stimulated at
    rest, neuron 0 reads -70 + 40 = -30 mV (a spike) and neuron 1 reads -70 + 20 = -50 mV
    one step later (the threshold: a spike). The pattern wants one spike, at
    ``pattern_step``: 0.5 for it, 0.5 / 5 = 0.1 for each of the five silences."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 1] = 1
    pattern = np.zeros(LENGTH, dtype=bool)
    pattern[pattern_step] = True
    return ContextSet([Context(weights, 1, pattern)], NeuronParams())


def episode(latency: int, actions, contexts: ContextSet | None = None):
    """(observations [N + 1], rewards [N], spikes [N, n]) of the chain under ``actions``."""
    env = NeuronControlEnv(contexts=chain() if contexts is None else contexts,
                           extensions={"latency_steps": latency})  # fmt: skip
    observation, _ = env.reset(seed=0, options={"context": 0})
    observations, rewards, spikes = [observation], [], []
    for action in actions:
        observation, reward, _, _, info = env.step(action)
        observations.append(observation)
        rewards.append(reward)
        spikes.append(info["spikes"])
    return observations, np.array(rewards), np.array(spikes)


# -- the hand-computed chain


@pytest.mark.parametrize("latency", [0, 1, 2])
def test_a_stimulation_lands_latency_steps_after_it_is_chosen(latency):
    """Neuron 0 chosen at step 0 spikes at step L, the target at L + 1; the observations
    show -30 mV after step L and -50 mV (the target) after step L + 1."""
    observations, rewards, spikes = episode(latency, [0] + [DO_NOTHING] * (LENGTH - 1))
    expected = np.zeros((LENGTH, 3), dtype=bool)
    expected[latency, 0] = expected[latency + 1, 1] = True
    np.testing.assert_array_equal(spikes, expected)
    np.testing.assert_allclose(observations[latency + 1]["voltage"], [-30.0, -70.0, -70.0])
    np.testing.assert_allclose(observations[latency + 2]["voltage"], [-70.0, -50.0, -70.0])
    for s in range(latency + 1):  # nothing landed yet: all at rest
        np.testing.assert_allclose(observations[s]["voltage"], -70.0)
    # The reward is for the step's own spikes: the target spiked at L + 1, wanted at 3.
    expected_rewards = np.full(LENGTH, 0.1)
    expected_rewards[3] = 0.5 if latency + 1 == 3 else 0.0
    expected_rewards[latency + 1] = 0.5 if latency + 1 == 3 else 0.0
    np.testing.assert_allclose(rewards, expected_rewards)


@pytest.mark.parametrize("latency", [0, 1, 2])
def test_choosing_latency_steps_early_meets_the_pattern(latency):
    """The target must spike at step 3: neuron 0 chosen at step 2 - L does it (return
    1); chosen at step 2 regardless of the latency it misses by L steps (0.4 for L > 0)."""
    early = [DO_NOTHING] * LENGTH
    early[2 - latency] = 0
    assert episode(latency, early)[1].sum() == pytest.approx(1.0)
    unaware = [DO_NOTHING] * LENGTH
    unaware[2] = 0
    assert episode(latency, unaware)[1].sum() == pytest.approx(1.0 if latency == 0 else 0.4)


@pytest.mark.parametrize("latency", [1, 2])
def test_the_last_latency_steps_actions_never_land(latency):
    actions = [DO_NOTHING] * LENGTH
    actions[LENGTH - latency] = 0
    _, rewards, spikes = episode(latency, actions)
    assert not spikes.any()
    assert rewards.sum() == pytest.approx(0.5)  # the five silences, not the spike


def test_the_observation_carries_the_actions_in_flight_oldest_first():
    """Chosen 0, -1, 2, 0, ... with L = 2: in flight at step s are the choices of s - 2
    and s - 1 (-1 before the start); last_action stays the latest choice."""
    chosen = [0, DO_NOTHING, 2, 0, DO_NOTHING, DO_NOTHING]
    observations, _, _ = episode(2, chosen)
    in_flight = [observation[IN_FLIGHT_KEY].tolist() for observation in observations]
    assert in_flight == [[-1, -1], [-1, 0], [0, -1], [-1, 2], [2, 0], [0, -1], [-1, -1]]
    assert [o["last_action"] for o in observations] == [DO_NOTHING, *chosen]
    assert all(o[IN_FLIGHT_KEY].dtype == np.int64 for o in observations)


def test_the_mask_applies_to_the_chosen_action():
    """The target stays illegal to choose under latency (it would land on the target)."""
    env = NeuronControlEnv(contexts=chain(), extensions={"latency_steps": 1})
    _, info = env.reset(seed=0)
    assert info["action_mask"].tolist() == [1, 1, 0, 1]
    with pytest.raises(ValueError, match="stimulates the target neuron 1"):
        env.step(1)


def test_without_latency_the_spaces_and_observations_are_the_papers():
    plain = NeuronControlEnv(**SHORT)
    zero = NeuronControlEnv(**SHORT, extensions={"latency_steps": 0})
    assert zero.observation_space == plain.observation_space == observation_space(8, 12)
    assert IN_FLIGHT_KEY not in plain.observation_space.spaces
    a, _ = plain.reset(seed=3)
    b, _ = zero.reset(seed=3)
    assert a.keys() == b.keys() and all(np.array_equal(a[key], b[key]) for key in a)
    delay = ActionDelay(2, 0)
    chosen = np.array([3, -1])
    assert delay.push(chosen) is chosen and delay.push_one(4) == 4  # untouched: no copy


def test_the_space_holds_every_observation_and_the_env_checker_passes():
    env = NeuronControlEnv(**SHORT, extensions={"latency_steps": 3})
    space = env.observation_space[IN_FLIGHT_KEY]
    assert space == gym.spaces.MultiDiscrete(np.full(3, 9), start=np.full(3, -1))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*infinity.*")
        check_env(env, skip_render_check=True)
    observation, info = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(env.episode_length):
        assert observation in env.observation_space
        action = int(rng.choice(np.flatnonzero(info["action_mask"]))) - 1
        observation, _, _, _, info = env.step(action)


def test_an_episode_pickled_mid_way_continues_identically():
    env = NeuronControlEnv(**SHORT, extensions={"latency_steps": 2})
    env.reset(seed=5)
    for action in (0, 3, 4):
        env.step(action if env.action_space.legal_mask[action + 1] else DO_NOTHING)
    copy = pickle.loads(pickle.dumps(env))
    for _ in range(4):
        a, ra, *_ = env.step(DO_NOTHING)
        b, rb, *_ = copy.step(DO_NOTHING)
        assert ra == rb and all(np.array_equal(a[key], b[key]) for key in a)


# -- bad settings


@pytest.mark.parametrize("value", [-1, 6, 1.5, True, "1", None])
def test_a_bad_latency_is_one_named_line(value):
    with pytest.raises(ConfigError, match=r"Extensions\.latency_steps must") as error:
        Extensions(latency_steps=value)
    assert "\n" not in str(error.value)
    with pytest.raises(ConfigError, match="latency_steps"):
        NeuronControlEnv(**SHORT, extensions={"latency_steps": value})


def test_plan_episode_refuses_a_bad_latency():
    context = chain()[0]
    for value in (-1, 6, 1.5, True):
        with pytest.raises(ValueError, match="latency_steps must be an integer in 0..5"):
            plan_episode(context, latency_steps=value)


# -- the vector environment


@pytest.mark.parametrize("extensions", [
    {"latency_steps": 1},
    {"latency_steps": 3, "hidden_fraction": 0.25, "stochastic_release": True,
     "observation_noise_mV": 1.0},
    {"sensing": "spikes"},
    {"sensing": "spikes", "latency_steps": 2, "hidden_neurons": 2},
    registered_kwargs("spikectl/NeuronControlRig-v0")["extensions"],
], ids=["latency1", "latency3-realistic", "spikes", "spikes-latency2-hidden", "rig"])  # fmt: skip
def test_the_vector_env_equals_single_envs_through_the_loop(extensions):
    """The batched loop (latency, spikes-only sensing, the rig) gives the single
    environments' episodes, step for step, over three episodes with their autoresets
    (the queues restart empty, the spikes cleared)."""
    num_envs = 4
    kwargs = {**SHORT, "extensions": extensions}
    spikes_only = extensions.get("sensing") == "spikes"
    batched = NeuronControlVectorEnv(num_envs=num_envs, **kwargs)
    sync = SyncVectorEnv([lambda: NeuronControlEnv(**kwargs) for _ in range(num_envs)],
                         autoreset_mode=AutoresetMode.NEXT_STEP)  # fmt: skip
    assert batched.single_observation_space == sync.single_observation_space
    obs_a, info_a = batched.reset(seed=7)
    obs_b, _ = sync.reset(seed=7)
    rng = np.random.default_rng(13)
    spiked = 0
    for step in range(3 * 13 + 2):
        assert set(obs_a) == set(obs_b)
        assert (IN_FLIGHT_KEY in obs_a) == bool(extensions.get("latency_steps"))
        assert ("voltage" in obs_a) != spikes_only and (SPIKES_KEY in obs_a) == spikes_only
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key], err_msg=f"{step} {key}")
        assert obs_a in batched.observation_space
        spiked += int(obs_a[SPIKES_KEY].sum()) if spikes_only else 0
        actions = np.array([rng.choice(np.flatnonzero(m)) - 1 for m in info_a["action_mask"]])
        obs_a, info_a, obs_b = step_alike(batched, sync, actions)
    assert spiked > 0 or not spikes_only  # spikes were compared, not only zeros


def test_the_vector_env_renders_the_actions_as_they_land():
    """Both environments keep the actions that stimulated (aligned with the spikes)."""
    contexts = chain()
    single = NeuronControlEnv(contexts=contexts, extensions={"latency_steps": 2})
    batched = NeuronControlVectorEnv(1, contexts=contexts, extensions={"latency_steps": 2})
    single.reset(seed=0)
    batched.reset(seed=0)
    for action in (0, 2, DO_NOTHING):
        single.step(action)
        batched.step(np.array([action]))
    assert single._action_history[0, :3].tolist() == [-1, -1, 0]
    assert batched._action_history[0, :3].tolist() == [-1, -1, 0]


# -- the flat wrappers


def test_the_flat_layout_appends_one_hot_actions_in_flight():
    """With L = 2 the flat vector is the paper's 3k + 3N + 2 entries, unchanged, then two
    one-hot blocks of k + 1 (zero-based: 0 does nothing); the Dict form is zero-based."""
    kwargs = {**SHORT, "extensions": {"latency_steps": 2}}
    flat, plain = FlatNeuronControlEnv(**kwargs), FlatNeuronControlEnv(**SHORT)
    k, base = 8, 3 * 8 + 3 * 12 + 2
    assert flat.observation_space.shape == (base + 2 * (k + 1),)
    assert plain.observation_space.shape == (base,)
    np.testing.assert_array_equal(flat.observation_space.low[:base], plain.observation_space.low)
    np.testing.assert_array_equal(flat.observation_space.high[base:], 1.0)
    np.testing.assert_array_equal(flat.observation_space.low[base:], 0.0)
    observation, info = flat.reset(seed=2)
    paper = flat.env
    assert observation[base:].tolist() == [1.0] + [0.0] * k + [1.0] + [0.0] * k
    legal = np.flatnonzero(info["action_mask"])  # zero-based
    first, second = int(legal[1]), int(legal[2])
    flat.step(first)
    observation, *_ = flat.step(second)
    blocks = observation[base:].reshape(2, k + 1)
    assert blocks.sum(axis=1).tolist() == [1.0, 1.0]
    assert blocks.argmax(axis=1).tolist() == [first, second]
    np.testing.assert_array_equal(paper._delay.in_flight[0] + 1, [first, second])
    unflattened = FlatNeuronControlEnv(**kwargs).observation_codec
    as_dict = type(unflattened)(8, 8, 12, NeuronParams(), flatten=False, latency_steps=2)
    converted = as_dict({**paper.reset(seed=2)[0], IN_FLIGHT_KEY: np.array([-1, 4])})
    assert converted[IN_FLIGHT_KEY].tolist() == [0, 5]
    assert as_dict.space[IN_FLIGHT_KEY] == gym.spaces.MultiDiscrete([9, 9])


@pytest.mark.parametrize("extensions", [
    {"latency_steps": 2},
    {"sensing": "spikes", "latency_steps": 1},
    registered_kwargs("spikectl/NeuronControlRig-v0")["extensions"],
], ids=["latency2", "spikes-latency1", "rig"])  # fmt: skip
def test_the_flat_vector_env_equals_the_flat_env_through_the_loop(extensions):
    """The batched flat environment steps as the single ones, with the actions in flight
    and spikes-only sensing in the flat layout (and the rig's ChR2 and background)."""
    kwargs = {**SHORT, "extensions": extensions}
    assert_flat_vector_env_steps_as_singles(FlatNeuronControlVectorEnv, FlatNeuronControlEnv,
                                            kwargs, 12)  # fmt: skip


def test_the_latency_ids_are_registered_with_flat_twins():
    for latency in (1, 2):
        env_id = f"spikectl/NeuronControlLatency{latency}-v0"
        env = gym.make(env_id, contexts={"n_train": 4, "n_test": 4})
        assert env.unwrapped.extensions.latency_steps == latency
        assert env.observation_space[IN_FLIGHT_KEY].shape == (latency,)
        flat = gym.make(flat_id(env_id), contexts={"n_train": 4, "n_test": 4})
        assert flat.observation_space.shape == (3 * 8 + 3 * 60 + 2 + latency * 9,)
        vector = gym.make_vec(env_id, num_envs=2, contexts={"n_train": 4, "n_test": 4})
        assert isinstance(vector.unwrapped, NeuronControlVectorEnv)
        assert vector.unwrapped._delay.steps == latency


# -- the oracle


@pytest.mark.parametrize("latency", [0, 1, 2])
def test_the_oracle_plans_for_the_latency_it_plays(latency):
    """On the chain the latency-aware oracle meets the pattern (return 1) under every
    latency; planning without it, it scores less, and plan_episode's return is what the
    environment gives its actions."""
    contexts = chain()
    actions, planned = plan_episode(contexts[0], latency_steps=latency)
    assert planned == pytest.approx(1.0)
    assert (actions[LENGTH - latency :] == DO_NOTHING).all()
    assert episode(latency, actions.tolist())[1].sum() == pytest.approx(planned)
    env = NeuronControlEnv(contexts=contexts, extensions={"latency_steps": latency})
    _, aware = play_episode(env, OraclePlanner(contexts), 0)
    _, unaware = play_episode(env, OraclePlanner(contexts, latency_steps=0), 0)
    assert aware == pytest.approx(1.0)
    assert unaware == pytest.approx(1.0 if latency == 0 else 0.4)


def test_the_aware_oracle_beats_the_unaware_one_on_generated_networks():
    """On 12 generated networks under latency 1 and 2: the aware oracle is at least the
    unaware one on every network and well above doing nothing in the mean; the batch
    (one planner for the vector env) equals the single env's play."""
    env = NeuronControlEnv(contexts={"n_train": 2, "n_test": 12, "seed": 3}, split="test")
    contexts = env.contexts
    for latency in (1, 2):
        extensions = Extensions(latency_steps=latency)
        aware = evaluate_policy(contexts, OraclePlanner(contexts, width=32),
                                extensions=extensions).returns  # fmt: skip
        unaware = evaluate_policy(contexts, OraclePlanner(contexts, width=32, latency_steps=0),
                                  extensions=extensions).returns  # fmt: skip
        nothing = evaluate_policy(contexts, DoNothing(), extensions=extensions).returns
        assert (aware >= unaware - 1e-12).all()
        assert aware.mean() > nothing.mean() + 0.3 > unaware.mean() + 0.3
        single = NeuronControlEnv(contexts=contexts, extensions=extensions)
        oracle = OraclePlanner(contexts, width=32)
        for c in (0, 5):
            assert play_episode(single, oracle, c)[1] == pytest.approx(aware[c], abs=1e-12)
