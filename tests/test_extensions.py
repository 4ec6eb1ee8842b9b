"""The extensions (docs/extensions.md): each one's effect, off = the paper bit for bit."""

from __future__ import annotations

import hashlib
import json
import math
import os
import pickle
import re
import subprocess
import sys
import time
import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from spikectl import simulate
from spikectl.contexts import ContextSet, NeuronSetup, make_context, make_splits
from spikectl.contexts.generation import generate_topology
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.registration import VARIANTS
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import EnvironmentEffects, Extensions, Heterogeneity
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import PARALLEL_MIN_BATCH, PARALLEL_MIN_WORK

SMALL = {"contexts": {"n_train": 10, "n_test": 10}}
SHORT = {"contexts": {"n_train": 6, "n_test": 2}, "episode_length": 12}
HETEROGENEOUS = Extensions(threshold_spread=0.2, time_constant_spread=0.3, synaptic_spread=0.25)
EVERYTHING = Extensions(
    hidden_fraction=0.25,
    threshold_spread=0.1,
    time_constant_spread=0.1,
    synaptic_spread=0.1,
    observation_noise_mV=1.0,
    bleaching_time_constant_steps=30.0,
    stochastic_release=True,
    background_rate=0.02,
)
UNBOUNDED_BOX = re.compile(r"Box observation space (minimum|maximum) value is -?infinity")
PARAMS = NeuronParams()


def play(env, actions, context, seed=0):
    """Observations [T + 1, k], rewards [T], spikes [T, k] of one episode."""
    obs, _ = env.reset(seed=seed, options={"context": context})
    voltages, rewards, spikes = [obs["voltage"]], [], []
    for action in actions:
        obs, reward, _, _, info = env.step(int(action))
        voltages.append(obs["voltage"])
        rewards.append(reward)
        spikes.append(info["spikes"])
    return np.array(voltages), np.array(rewards), np.array(spikes)


def random_actions(env, rng, length=None):
    """Uniform legal actions of the env's current context (call after a reset)."""
    mask = env.action_space.legal_mask.astype(bool)
    return rng.choice(np.flatnonzero(mask) - 1, size=length or env.episode_length)


# -- the settings


def test_defaults_are_the_paper_and_round_trip():
    default = Extensions()
    assert not (default.heterogeneous or default.random_dynamics or default.transforms_observation)
    assert default.hidden_count(8) == 0 and default.to_dict(only_changed=True) == {}
    assert Extensions.from_dict(EVERYTHING.to_dict()) == EVERYTHING
    assert Extensions.coerce(None) == default and Extensions.coerce({"background_rate": 0.1})
    assert json.loads(json.dumps(EVERYTHING.to_dict())) == EVERYTHING.to_dict()
    assert EVERYTHING.context_part() == Extensions(
        hidden_fraction=0.25, threshold_spread=0.1, time_constant_spread=0.1, synaptic_spread=0.1
    )
    assert EVERYTHING.environment_part().context_part() == default
    assert Extensions(hidden_fraction=0.25).hidden_count(8) == 2
    assert Extensions(hidden_fraction=0.3).hidden_count(5) == 2  # 1.5 rounds up


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"observation_noise_mV": -1.0}, ValueError, "observation_noise_mV must be >= 0"),
        ({"observation_noise_mV": math.nan}, ValueError, "finite"),
        ({"threshold_spread": 1.0}, ValueError, r"threshold_spread must lie in \[0, 1\)"),
        ({"hidden_fraction": -0.1}, ValueError, "hidden_fraction"),
        ({"hidden_neurons": 2, "hidden_fraction": 0.25}, ValueError, "not both"),
        ({"hidden_neurons": 1.5}, TypeError, "hidden_neurons must be an integer"),
        ({"stochastic_release": 1}, TypeError, "stochastic_release must be a bool"),
        ({"bleaching_time_constant_steps": 0}, ValueError, "bleaching_time_constant_steps"),
        ({"background_rate": "0.1"}, TypeError, "background_rate must be a number"),
    ],
)
def test_bad_settings_raise_clear_errors(kwargs, error, message):
    with pytest.raises(error, match=message):
        Extensions(**kwargs)


def test_bad_uses_raise_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown Extensions field"):
        Extensions.from_dict({"noise": 1.0})
    with pytest.raises(TypeError, match="extensions must be"):
        NeuronControlEnv(extensions=0.5, **SMALL)
    with pytest.raises(ValueError, match="fewer than 2 observable"):
        ContextSet.generate(2, n_neurons=4, extensions=Extensions(hidden_neurons=3))
    with pytest.raises(ValueError, match="below dt"):
        ContextSet.generate(2, extensions=Extensions(time_constant_spread=0.99))
    plain = ContextSet.generate(2)
    with pytest.raises(ValueError, match="belong to the contexts"):
        NeuronControlEnv(contexts=plain, extensions={"hidden_neurons": 2})
    weights = np.array([[0, 1, 0], [0, 0, 1], [0, 0, 0]])
    with pytest.raises(ValueError, match="cannot be hidden"):
        make_context(weights, target=2, neurons=NeuronSetup(hidden=[2]))
    with pytest.raises(ValueError, match="hidden neurons"):
        make_context(weights, target=1, pattern=[0, 1, 0], witness=[2, -1, -1],
                     neurons=NeuronSetup(hidden=[2]))  # fmt: skip
    with pytest.raises(ValueError, match="synaptic_scale must have shape"):
        simulate(weights, [0], synaptic_scale=np.ones((2, 2)))
    with pytest.raises(ValueError, match="release_uniforms must lie in"):
        simulate(weights, [0], release_uniforms=np.full((1, 3), 2.0))
    with pytest.raises(ValueError, match="thresholds_mV must lie above"):
        simulate(weights, [0], thresholds_mV=np.full(3, -80.0))


# -- off is the paper, bit for bit


def test_everything_off_is_the_paper_bit_for_bit():
    off = Extensions(bleaching_time_constant_steps=None, background_current_pA=-50.0)
    assert make_splits(20, 5, seed=3) == make_splits(20, 5, seed=3, extensions=off)
    paper, explicit = NeuronControlEnv(**SMALL), NeuronControlEnv(extensions=off, **SMALL)
    rng = np.random.default_rng(1)
    for context in range(4):
        paper.reset(options={"context": context})
        actions = random_actions(paper, rng)
        episodes = play(paper, actions, context), play(explicit, actions, context)
        for a, b in zip(*episodes, strict=True):
            np.testing.assert_array_equal(a, b)
    # The simulator's extension inputs at their neutral values change nothing either.
    weights = np.stack([c.weights for c in paper.contexts])
    actions = rng.integers(-1, 8, size=(len(weights), 60))
    voltages, spikes = simulate(weights, actions)
    neutral = simulate(
        weights, actions,
        thresholds_mV=np.full(8, -50.0), membrane_time_constants_ms=np.full(8, 20.0),
        synaptic_scale=np.ones((8, 8)), input_mV=np.zeros((60, 8)),
    )  # fmt: skip
    np.testing.assert_array_equal(neutral[0], voltages)
    np.testing.assert_array_equal(neutral[1], spikes)


# Digests of the paper's results computed with the code as it was before the extensions.
PINNED_CONTEXTS = "90e5be0d331bc0f3ea1b08e34387d2c9df6486cff554de7f8375c5361b8b38a4"
PINNED_SIMULATION = "7e667cec5061378522adbb776bf00183f36c50bf6c395bf8614677ebe64f79c1"
PINNED_EPISODES = "15962fac0c52756d9fb87ff16abde0b1595a2b98d1e32530b665e7558deed205"


@pytest.mark.parametrize("extensions", [None, Extensions()], ids=["default", "explicit-off"])
def test_the_paper_is_unchanged_by_the_extension_code(extensions):
    assert ContextSet.generate(20, seed=0, extensions=extensions).checksum() == PINNED_CONTEXTS
    rng = np.random.default_rng(0)
    weights = np.stack([generate_topology(8, rng) for _ in range(16)])
    voltages, spikes = simulate(weights, rng.integers(-1, 8, size=(16, 60)))
    assert hashlib.sha256(voltages.tobytes() + spikes.tobytes()).hexdigest() == PINNED_SIMULATION
    env = NeuronControlEnv(extensions=extensions, **SMALL)
    digest = hashlib.sha256()
    _, info = env.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(3):
        terminated = False
        while not terminated:
            action = int(rng.choice(np.flatnonzero(info["action_mask"]) - 1))
            obs, reward, terminated, _, info = env.step(action)
            digest.update(obs["voltage"].tobytes())
            digest.update(np.float64(reward).tobytes())
            digest.update(info["spikes"].tobytes())
        _, info = env.reset()
    assert digest.hexdigest() == PINNED_EPISODES


# -- measurement noise, photobleaching


def test_measurement_noise_is_gaussian_with_sigma_and_leaves_the_dynamics_alone():
    sigma = 1.5
    plain, noisy = (
        NeuronControlEnv(**SMALL),
        NeuronControlEnv(extensions={"observation_noise_mV": sigma}, **SMALL),
    )
    rng = np.random.default_rng(2)
    differences = []
    for context in range(6):
        plain.reset(options={"context": context})
        actions = random_actions(plain, rng)
        true_v, true_r, true_s = play(plain, actions, context)
        seen_v, seen_r, seen_s = play(noisy, actions, context, seed=context)
        np.testing.assert_array_equal(seen_r, true_r)  # the dynamics are untouched
        np.testing.assert_array_equal(seen_s, true_s)
        differences.append(seen_v.astype(np.float64) - true_v)
    noise = np.concatenate(differences).ravel()  # 6 * 61 * 8 = 2928 samples
    assert abs(noise.mean()) < 4 * sigma / math.sqrt(noise.size)
    assert noise.std() == pytest.approx(sigma, rel=0.06)


def test_photobleaching_follows_the_exponential_decay():
    tau = 25.0
    plain = NeuronControlEnv(**SMALL)
    bleached = NeuronControlEnv(extensions={"bleaching_time_constant_steps": tau}, **SMALL)
    plain.reset(options={"context": 0})
    actions = random_actions(plain, np.random.default_rng(3))
    true_v = play(plain, actions, 0)[0].astype(np.float64)
    seen_v = play(bleached, actions, 0)[0].astype(np.float64)
    steps = np.arange(len(true_v))[:, None]
    expected = -70.0 + (true_v + 70.0) * np.exp(-steps / tau)
    np.testing.assert_allclose(seen_v, expected, rtol=0, atol=1e-4)
    assert (true_v > -70).any()  # there was a signal to bleach


# -- hidden neurons


def test_hidden_neurons_are_never_observed_stimulated_or_the_target():
    extensions = Extensions(hidden_neurons=3)
    train, _ = make_splits(15, 2, seed=4, extensions=extensions)
    env = NeuronControlEnv(contexts=train)
    assert env.extensions.hidden_neurons == 3 and env.n_observed == 5
    assert env.observation_space["voltage"].shape == (5,)
    assert env.action_space == gym.spaces.Discrete(6, start=-1)
    rng = np.random.default_rng(5)
    for index, context in enumerate(train):
        assert context.hidden.size == 3 and context.target not in context.hidden
        assert context.verify_witness()
        obs, info = env.reset(options={"context": index})
        assert obs["target"] == context.observed_target
        assert context.observable[obs["target"]] == context.target
        legal_neurons = context.observable[np.flatnonzero(info["action_mask"][1:])]
        assert not set(legal_neurons) & (set(context.hidden) | {context.target})
        # What the agent sees is exactly the observable neurons of the full network.
        actions = random_actions(env, rng)
        seen_v, rewards, seen_s = play(env, actions, index)
        neuron_actions = np.where(actions >= 0, context.observable[np.maximum(actions, 0)], -1)
        true_v, true_s = simulate(context.weights, neuron_actions)
        np.testing.assert_array_equal(seen_v[1:], true_v[:, context.observable].astype(np.float32))
        np.testing.assert_array_equal(seen_s, true_s[:, context.observable])
        # The witness (in the agent's indices) still proves reachability.
        assert play(env, context.agent_witness, index)[1].sum() == pytest.approx(1.0, abs=1e-12)
    env.reset()
    with pytest.raises(ValueError, match="out of range"):
        env.step(5)


# -- heterogeneous neurons


def test_heterogeneous_neurons_lie_within_their_spread_and_change_the_dynamics():
    train, _ = make_splits(12, 2, seed=6, extensions=HETEROGENEOUS)
    env = NeuronControlEnv(contexts=train)
    rng = np.random.default_rng(7)
    changed = 0
    for index, context in enumerate(train):
        h = context.heterogeneity
        assert np.all(np.abs((h.thresholds_mV + 70.0) / 20.0 - 1.0) <= 0.2)
        assert np.all(np.abs(h.time_constants_ms / 20.0 - 1.0) <= 0.3)
        edges = context.weights != 0
        assert np.all(np.abs(h.synaptic_scale[edges] - 1.0) <= 0.25)
        assert np.all(h.synaptic_scale[~edges] == 1.0)
        assert np.unique(h.thresholds_mV).size == 8  # neurons really differ
        assert context.verify_witness()
        assert play(env, context.witness, index)[1].sum() == pytest.approx(1.0, abs=1e-12)
        actions = rng.integers(-1, 8, size=60)
        changed += not np.array_equal(
            simulate(context.weights, actions, **context.simulate_kwargs())[0],
            simulate(context.weights, actions)[0],
        )
    assert changed == len(train)


def test_per_neuron_threshold_and_time_constant_by_hand():
    weights = np.array([[0, 1, 1], [0, 0, 0], [0, 0, 0]])
    # Neuron 1 needs 21 mV: one input (20 mV) does not fire it; neuron 2 (tau 10 ms) leaks
    # twice as fast as the paper's 20 ms.
    voltages, spikes = simulate(
        weights, [0, -1, -1], thresholds_mV=[-50.0, -49.0, -50.0],
        membrane_time_constants_ms=[20.0, 20.0, 10.0],
        synaptic_scale=np.array([[1, 1, 0.5], [1, 1, 1], [1, 1, 1]]),
    )  # fmt: skip
    assert spikes[1].tolist() == [False, False, False]
    assert voltages[1, 1] == -50.0 and voltages[2, 1] == pytest.approx(-70 + 20 * 0.95)
    assert voltages[1, 2] == -60.0 and voltages[2, 2] == pytest.approx(-70 + 10 * 0.9)


# -- stochastic release


def test_release_frequency_is_p_r_times_recovery():
    """Neuron 0 is stimulated every other step; 0 -> 1 fires 1 exactly when 0 released."""
    steps = 6000
    weights = np.array([[0, 1], [0, 0]])
    actions = np.where(np.arange(steps) % 2 == 0, 0, -1)
    uniforms = np.random.default_rng(8).random((steps, 2))
    _, spikes = simulate(weights, actions, release_uniforms=uniforms)
    assert spikes[::2, 0].all()
    released = spikes[1:, 1]  # step t + 1 shows the release at t
    since, probabilities, outcomes = math.inf, [], []
    for t in range(0, steps - 1, 2):
        since += 2
        probability = 0.65 * (1 - math.exp(-since / 3.0))
        probabilities.append(probability)
        outcomes.append(released[t])
        if released[t]:
            since = 0
        assert released[t] == (uniforms[t, 0] < probability)  # the rule, draw by draw
    probabilities, outcomes = np.array(probabilities), np.array(outcomes)
    spread = math.sqrt((probabilities * (1 - probabilities)).sum())
    assert abs(outcomes.sum() - probabilities.sum()) < 4 * spread
    for value in np.unique(probabilities):  # each recovery level on its own
        chosen = probabilities == value
        if chosen.sum() > 200:
            assert outcomes[chosen].mean() == pytest.approx(value, abs=0.08)


def test_stochastic_environment_is_reproducible_from_its_seed():
    env_a = NeuronControlEnv(extensions={"stochastic_release": True}, **SMALL)
    env_b = NeuronControlEnv(extensions={"stochastic_release": True}, **SMALL)
    env_a.reset(options={"context": 1})
    actions = random_actions(env_a, np.random.default_rng(9))
    first = play(env_a, actions, 1, seed=11)
    for a, b in zip(first, play(env_b, actions, 1, seed=11), strict=True):
        np.testing.assert_array_equal(a, b)
    others = [play(env_b, actions, 1, seed=seed)[2] for seed in range(12, 20)]
    assert any(not np.array_equal(first[2], spikes) for spikes in others)


# -- background activity


def test_background_input_rate():
    rate = 0.1
    model = EnvironmentEffects(Extensions(background_rate=rate), PARAMS, 60)
    rng = np.random.default_rng(10)
    steps, n = 4000, 8
    inputs = np.zeros((steps, n))
    for t in range(steps):
        model.draw_inputs(rng, None, inputs[t])
    counts = inputs / 20.0  # 600 pA for 1 ms on 30 pF: 20 mV per input
    np.testing.assert_array_equal(counts, np.round(counts))
    assert counts.mean() == pytest.approx(rate, abs=4 * math.sqrt(rate / counts.size))
    # Isolated neurons at rest fire on an input unless refractory: rate q / (1 + q).
    _, spikes = simulate(np.zeros((n, n)), np.full(steps, -1), input_mV=inputs)
    q = 1 - math.exp(-rate)
    expected = q / (1 + q)
    assert spikes.mean() == pytest.approx(expected, abs=4 * math.sqrt(expected / spikes.size))


def test_background_activity_drives_an_idle_environment():
    env = NeuronControlEnv(extensions={"background_rate": 0.05}, **SMALL)
    spikes = play(env, np.full(60, -1), 0, seed=1)[2]
    assert spikes.any()  # the paper's network never spikes without stimulation
    np.testing.assert_array_equal(spikes, play(env, np.full(60, -1), 0, seed=1)[2])


# -- the target as an action


@pytest.mark.parametrize("how", ["extensions", "with hidden neurons"])
def test_the_target_can_be_made_an_action(how):
    extensions = {"allow_target_action": True}
    contexts = SMALL["contexts"]
    if how == "with hidden neurons":
        contexts, _ = make_splits(5, 1, seed=2, extensions={"hidden_neurons": 2})
    env = NeuronControlEnv(contexts=contexts, extensions=extensions)
    assert env.extensions.allow_target_action
    obs, info = env.reset(options={"context": 0})
    assert info["action_mask"].all()
    _, _, _, _, info = env.step(int(obs["target"]))
    assert info["target_spiked"] and info["spikes"][obs["target"]]
    strict = NeuronControlEnv(contexts=contexts)
    target = int(strict.reset(options={"context": 0})[0]["target"])
    with pytest.raises(ValueError, match="extensions=\\{'allow_target_action': True\\} allows it"):
        strict.step(target)


# -- determinism, pickling, the vector environment


def test_realistic_env_is_deterministic_and_pickles_mid_episode():
    env = NeuronControlEnv(extensions=EVERYTHING, **SMALL)
    rng = np.random.default_rng(12)
    _, info = env.reset(seed=4)
    for _ in range(20):
        env.step(int(rng.choice(np.flatnonzero(info["action_mask"])) - 1))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(70):  # the rest of the episode and the next
        if env._next_step == env.episode_length:
            a, b = env.reset(), clone.reset()
        else:
            action = int(rng.choice(np.flatnonzero(info["action_mask"])) - 1)
            a, b = env.step(action), clone.step(action)
        info = a[-1]
        for key in a[0]:
            np.testing.assert_array_equal(a[0][key], b[0][key])
        assert a[1:-1] == b[1:-1]


@pytest.mark.parametrize(
    "extensions",
    [
        Extensions(observation_noise_mV=2.0, bleaching_time_constant_steps=10.0),
        Extensions(hidden_neurons=3, allow_target_action=True),
        HETEROGENEOUS,
        Extensions(stochastic_release=True, background_rate=0.05),
        EVERYTHING,
    ],
    ids=["noise+bleaching", "hidden+target", "heterogeneous", "stochastic+background", "all"],
)
def test_vector_env_equals_sync_vector_env(extensions):
    num_envs = 4
    kwargs = {**SHORT, "extensions": extensions}
    batched = NeuronControlVectorEnv(num_envs=num_envs, **kwargs)
    sync = SyncVectorEnv(
        [lambda: NeuronControlEnv(**kwargs) for _ in range(num_envs)],
        autoreset_mode=AutoresetMode.NEXT_STEP,
    )
    assert batched.single_observation_space == sync.single_observation_space
    obs_a, info_a = batched.reset(seed=7)
    obs_b, _ = sync.reset(seed=7)
    rng = np.random.default_rng(13)
    for step in range(3 * 13 + 2):  # three episodes with their autoresets
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key], err_msg=f"{step} {key}")
        actions = np.array([rng.choice(np.flatnonzero(m)) - 1 for m in info_a["action_mask"]])
        obs_a, rewards_a, terminated_a, _, info_a = batched.step(actions)
        obs_b, rewards_b, terminated_b, _, info_b = sync.step(actions)
        np.testing.assert_array_equal(rewards_a, rewards_b)
        np.testing.assert_array_equal(terminated_a, terminated_b)
        for key in ("spikes", "target_spiked", "action_mask"):
            present = info_b.get(f"_{key}", np.zeros(num_envs, dtype=bool))
            np.testing.assert_array_equal(info_a[f"_{key}"], present)
            if present.any():
                np.testing.assert_array_equal(info_a[key][present], info_b[key][present])


@pytest.mark.slow  # 29 s; test_simulator checks the threaded kernel without extensions
def test_threaded_kernel_equals_serial_kernel_with_extensions():
    batch = max(PARALLEL_MIN_BATCH, PARALLEL_MIN_WORK // (20 * 6)) + 4  # threaded
    rng = np.random.default_rng(14)
    train, _ = make_splits(batch, 1, n_neurons=6, episode_length=20, seed=1,
                           extensions=HETEROGENEOUS)  # fmt: skip
    weights = np.stack([c.weights for c in train])
    kwargs = {
        "thresholds_mV": np.stack([c.heterogeneity.thresholds_mV for c in train]),
        "membrane_time_constants_ms": np.stack([c.heterogeneity.time_constants_ms for c in train]),
        "synaptic_scale": np.stack([c.heterogeneity.synaptic_scale for c in train]),
        "release_uniforms": rng.random((batch, 20, 6)),
        "input_mV": 20.0 * rng.poisson(0.05, (batch, 20, 6)),
    }
    actions = rng.integers(-1, 6, size=(batch, 20))
    threaded = simulate(weights, actions, **kwargs)
    half = batch // 2
    for part in (slice(0, half), slice(half, batch)):
        serial = simulate(weights[part], actions[part], **{k: v[part] for k, v in kwargs.items()})
        np.testing.assert_array_equal(serial[0], threaded[0][part])


def test_pure_python_path_matches_jit_with_extensions():
    rng = np.random.default_rng(15)
    weights = np.array([[0, 1, 1], [0, 0, 1], [-1, 0, 0]])
    kwargs = {
        "thresholds_mV": [-50.0, -49.0, -51.0],
        "membrane_time_constants_ms": [20.0, 15.0, 25.0],
        "release_uniforms": rng.random((30, 3)).tolist(),
        "input_mV": (5.0 * rng.poisson(0.2, (30, 3))).tolist(),
    }
    actions = rng.integers(-1, 3, size=30)
    voltages, _ = simulate(weights, actions, **kwargs)
    code = (
        "import json, sys, numpy as np; from spikectl import simulate; "
        "d = json.load(sys.stdin); v, s = simulate(np.array(d['w']), np.array(d['a']), **d['k']); "
        "print(json.dumps(v.tolist()))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        input=json.dumps({"w": weights.tolist(), "a": actions.tolist(), "k": kwargs}),
        capture_output=True, text=True, check=True,
        env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
    )  # fmt: skip
    np.testing.assert_array_equal(voltages, np.array(json.loads(result.stdout)))


# -- context sets, registered variants, larger networks


def test_context_sets_with_extensions_save_and_load(tmp_path):
    extensions = Extensions(hidden_fraction=0.25, threshold_spread=0.1, synaptic_spread=0.1)
    original = ContextSet.generate(5, seed=3, extensions=extensions)
    path = original.save(tmp_path / "set.npz")
    loaded = ContextSet.load(path)
    assert loaded == original and loaded.extensions == extensions
    with np.load(path) as data:
        assert json.loads(str(data["metadata"]))["format_version"] == 2
        assert data["hidden"].shape == (5, 2) and data["synaptic_scale"].shape == (5, 8, 8)
    with np.load(ContextSet.generate(2).save(tmp_path / "paper.npz")) as data:
        assert json.loads(str(data["metadata"]))["format_version"] == 1
    env = NeuronControlEnv(contexts=path, extensions={"observation_noise_mV": 1.0})
    assert env.extensions == replace(extensions, observation_noise_mV=1.0)
    assert isinstance(loaded[0].heterogeneity, Heterogeneity)


@pytest.mark.parametrize("env_id", sorted(VARIANTS))
def test_registered_variants_make_and_pass_the_checker(env_id):
    env = gym.make(env_id, **SMALL)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught if not UNBOUNDED_BOX.search(str(w.message))] == []
    assert json.loads(gym.spec(env_id).to_json())["kwargs"] == VARIANTS.entry(env_id)
    envs = gym.make_vec(env_id, num_envs=2, **SMALL)
    assert isinstance(envs, NeuronControlVectorEnv)
    obs, _ = envs.reset(seed=0)
    assert obs in envs.observation_space
    assert envs.step(envs.action_space.sample())[0] in envs.observation_space


def test_256_neurons_generate_and_play_an_episode():
    start = time.perf_counter()
    train, test = make_splits(4, 2, n_neurons=256, seed=0)
    assert time.perf_counter() - start < 10
    assert not train.duplicate_topologies(test)
    env = NeuronControlEnv(contexts=train)
    for index, context in enumerate(train):
        assert play(env, context.witness, index)[1].sum() == pytest.approx(1.0, abs=1e-12)
    envs = NeuronControlVectorEnv(num_envs=3, contexts=train, extensions={"background_rate": 0.01})
    obs, _ = envs.reset(seed=0)
    for _ in range(60):
        obs, _, terminated, _, _ = envs.step(envs.action_space.sample())
    assert obs["voltage"].shape == (3, 256) and terminated.all()
