"""A recording of a subset of neurons (``Extensions(sensing="spikes", recorded_neurons=m)``,
docs/extensions.md, "Spikes-only sensing"): per episode m of the k observed neurons are
recorded, the target always among them, drawn from the environment's own generator;
the others report no spike, and the observation's ``recorded`` marks which is which."""

from __future__ import annotations

import math
import pickle
import warnings

import numpy as np
import pytest
import torch
from conftest import assert_flat_vector_env_steps_as_singles, step_alike
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from spikectl.cli import main
from spikectl.config_errors import ConfigError, ConfigTypeError
from spikectl.contexts import Context, ContextSet
from spikectl.envs.controller import RandomLegal, first_decision_refusal
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.env_support import observation_space
from spikectl.envs.rollout import evaluate_policy
from spikectl.envs.sensing import RECORDED_KEY, SPIKES_KEY, Recording
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning import IdentifyAndPlan, named_composition
from spikectl.planning.oracle import OraclePlanner
from spikectl.training.loaders import load_controller
from spikectl.training.presets import SMOKE
from spikectl.training.run import train
from spikectl.wrappers.conventions import observation_for
from spikectl.wrappers.flat_env import FlatEnv, FlatNeuronControlEnv
from spikectl.wrappers.flat_vector_env import FlatNeuronControlVectorEnv

SPIKES = {"sensing": "spikes"}
RECORDED = {**SPIKES, "recorded_neurons": 3}
SHORT = {"contexts": {"n_train": 6, "n_test": 2}, "episode_length": 12}
REST, THRESHOLD = NeuronParams().v_rest_mV, NeuronParams().v_threshold_mV


def chain() -> ContextSet:
    """Neuron 0 excites neuron 1 (the target); neuron 2 is unconnected. Stimulated at rest,
    neuron 0 spikes at once and neuron 1 one step later (-70 + 20 = -50 mV)."""
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 1] = 1
    return ContextSet([Context(weights, 1, np.eye(1, 6, 1, dtype=bool)[0])], NeuronParams())


def random_episodes(env, seed: int, episodes: int = 2, contexts: list | None = None):
    """(observations, rewards, infos' spikes) of ``episodes`` random episodes, the actions
    seeded alike whatever the environment shows; on the given ``contexts`` (indices, one
    per episode), or on contexts the environment draws."""
    rng = np.random.default_rng(seed)
    chosen = [None] * episodes if contexts is None else contexts

    def reset(e: int, **seeding):
        return env.reset(**seeding, options=None if chosen[e] is None else {"context": chosen[e]})

    observation, info = reset(0, seed=seed)
    observations, rewards, spikes = [observation], [], []
    for episode in range(episodes):
        for _ in range(env.unwrapped.episode_length):
            action = int(rng.choice(np.flatnonzero(info["action_mask"]))) - 1
            observation, reward, _, _, info = env.step(action)
            observations.append(observation)
            rewards.append(reward)
            spikes.append(info["spikes"])
        if episode + 1 < episodes:
            observation, info = reset(episode + 1)
            observations.append(observation)
    return observations, rewards, spikes


# -- by hand


def test_the_chain_reports_only_the_recorded_neurons_spikes():
    """Stimulating 0 then 2 makes 0 spike at step 0, the target 1 at step 1 and 2 at step 2
    (info["spikes"], the simulator's); the observation shows those of the recorded ones."""
    seen_masks = set()
    for seed in range(12):
        env = NeuronControlEnv(contexts=chain(), extensions={**SPIKES, "recorded_neurons": 2})
        observation, _ = env.reset(seed=seed)
        mask = observation[RECORDED_KEY]
        assert mask.dtype == np.int8 and observation[SPIKES_KEY].tolist() == [0, 0, 0]
        seen, true = [], []
        for action in (0, DO_NOTHING, 2, DO_NOTHING, DO_NOTHING, DO_NOTHING):
            observation, *_, info = env.step(action)
            assert observation[RECORDED_KEY].tolist() == mask.tolist()  # fixed for the episode
            seen.append(observation[SPIKES_KEY].tolist())
            true.append(info["spikes"].astype(int).tolist())
        assert true == [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
        expected = {
            (1, 1, 0): [[1, 0, 0], [0, 1, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]],
            (0, 1, 1): [[0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0]],
        }[tuple(mask.tolist())]  # the target and one of the two others
        assert seen == expected
        seen_masks.add(tuple(mask.tolist()))
    assert seen_masks == {(1, 1, 0), (0, 1, 1)}  # both draws occurred, both were checked
    only_target = NeuronControlEnv(contexts=chain(), extensions={**SPIKES, "recorded_neurons": 1})
    assert only_target.reset(seed=0)[0][RECORDED_KEY].tolist() == [0, 1, 0]
    seen = [only_target.step(action)[0][SPIKES_KEY].tolist() for action in (0, DO_NOTHING, 2)]
    assert seen == [[0, 0, 0], [0, 1, 0], [0, 0, 0]]


def test_the_draw_records_the_others_with_the_smallest_uniforms():
    """rng.random(k) per environment, the target set below them all: seed 0 draws
    (0.637, 0.270, 0.041, 0.017, 0.813); with target 2 and m = 3 the two smallest others are
    neurons 3 and 1. Seed 1 draws (0.512, 0.950, 0.144, 0.949, 0.312); target 0, m = 2:
    neuron 2."""
    recording = Recording(2, 5, 3)
    recording.draw([np.random.default_rng(0)], np.array([1]), np.array([2]))
    assert recording.mask.tolist() == [[1] * 5, [0, 1, 1, 1, 0]]  # env 0 untouched
    recording = Recording(1, 5, 2)
    recording.draw([np.random.default_rng(1)], np.array([0]), np.array([0]))
    assert recording.mask.tolist() == [[1, 0, 1, 0, 0]]
    every = Recording(1, 5, 5)  # all recorded: nothing drawn
    rng = np.random.default_rng(4)
    every.draw([rng], np.array([0]), np.array([3]))
    assert every.mask.tolist() == [[1] * 5] and rng.random() == np.random.default_rng(4).random()


def test_the_target_is_always_recorded_and_the_others_uniformly():
    rng = np.random.default_rng(9)
    draws, k, m = 7000, 8, 3
    targets = rng.integers(0, k, draws)
    recording = Recording(draws, k, m)
    recording.draw([rng] * draws, np.arange(draws), targets)
    mask = recording.mask
    assert (mask.sum(axis=1) == m).all() and (mask[np.arange(draws), targets] == 1).all()
    others = np.ones_like(mask, dtype=bool)
    others[np.arange(draws), targets] = False
    frequency = mask[others].reshape(draws, k - 1).mean()
    assert frequency == pytest.approx((m - 1) / (k - 1), abs=1e-12)  # m - 1 of k - 1 each row
    per_neuron = (mask * others).sum(axis=0) / others.sum(axis=0)
    np.testing.assert_allclose(per_neuron, (m - 1) / (k - 1), atol=0.025)  # 4.6 s.e.


def test_the_mask_comes_from_the_environments_generator_after_the_context():
    env = NeuronControlEnv(**SHORT, extensions=RECORDED)
    for seed in (0, 5, 17):
        observation, info = env.reset(seed=seed)
        rng = np.random.default_rng(seed)  # Gymnasium seeds np_random as default_rng does
        assert info["context_index"] == rng.integers(len(env.contexts))
        expected = Recording(1, 8, 3)
        expected.draw([rng], np.array([0]), np.array([observation["target"]]))
        np.testing.assert_array_equal(observation[RECORDED_KEY], expected.mask[0])


# -- the environment


@pytest.mark.parametrize("extensions", [{}, {"hidden_neurons": 2, "latency_steps": 2}])
def test_recorded_neurons_report_exactly_the_simulators_spikes(extensions):
    """Same contexts, same actions, deterministic dynamics: the episodes are the
    spikes-only ones; the recorded neurons' spikes are theirs, the others' 0, and info
    keeps every one."""
    whole = NeuronControlEnv(**SHORT, extensions={**SPIKES, **extensions})
    part = NeuronControlEnv(**SHORT, extensions={**RECORDED, **extensions})
    a, ra, sa = random_episodes(whole, 3, episodes=4, contexts=[2, 0, 5, 2])
    b, rb, sb = random_episodes(part, 3, episodes=4, contexts=[2, 0, 5, 2])
    assert ra == rb
    np.testing.assert_array_equal(sa, sb)
    masks = set()
    for x, y in zip(a, b, strict=True):
        mask = y[RECORDED_KEY]
        assert mask.sum() == 3 and mask[y["target"]] == 1
        masks.add(tuple(mask))
        np.testing.assert_array_equal(y[SPIKES_KEY], x[SPIKES_KEY] * mask)
        assert set(y) - {RECORDED_KEY} == set(x)
        for key in set(x) - {SPIKES_KEY}:
            np.testing.assert_array_equal(x[key], y[key])
    assert len(masks) > 1  # drawn anew per episode
    pairs = zip(a, b, strict=True)
    unreported = sum(int((x[SPIKES_KEY] * (1 - y[RECORDED_KEY])).sum()) for x, y in pairs)
    assert unreported > 0  # some unrecorded neuron spiked and was not reported


def test_the_same_seed_gives_the_same_recording_and_another_seed_another():
    first = random_episodes(NeuronControlEnv(**SHORT, extensions=RECORDED), 4, episodes=3)[0]
    again = random_episodes(NeuronControlEnv(**SHORT, extensions=RECORDED), 4, episodes=3)[0]
    for x, y in zip(first, again, strict=True):
        assert all(np.array_equal(x[key], y[key]) for key in x)
    env = NeuronControlEnv(**SHORT, extensions=RECORDED)
    masks = {tuple(env.reset(seed=seed)[0][RECORDED_KEY]) for seed in range(10)}
    assert len(masks) > 1


def test_off_is_todays_spikes_only_and_all_recorded_draws_nothing():
    """None is the option off: no key, today's space and episodes. m = k records every
    neuron and draws nothing, so with background input (which draws every step) the
    episodes are today's, the mask all ones."""
    assert Extensions(**SPIKES, recorded_neurons=None) == Extensions(**SPIKES)
    assert "recorded_neurons" not in Extensions(**SPIKES).to_dict(only_changed=True)
    assert Extensions(**RECORDED).to_dict(only_changed=True) == RECORDED
    plain = NeuronControlEnv(**SHORT, extensions=SPIKES)
    assert plain.observation_space == observation_space(8, 12, 0, True)
    assert RECORDED_KEY not in plain.reset(seed=0)[0]
    noisy = {**SPIKES, "background_rate": 0.05}
    a, ra, sa = random_episodes(NeuronControlEnv(**SHORT, extensions=noisy), 6)
    b, rb, sb = random_episodes(
        NeuronControlEnv(**SHORT, extensions={**noisy, "recorded_neurons": 8}), 6
    )
    assert ra == rb
    np.testing.assert_array_equal(sa, sb)
    for x, y in zip(a, b, strict=True):
        assert y[RECORDED_KEY].tolist() == [1] * 8
        assert all(np.array_equal(x[key], y[key]) for key in x)


def test_the_space_holds_every_observation_the_checker_passes_and_it_pickles():
    env = NeuronControlEnv(**SHORT, extensions={**RECORDED, "latency_steps": 1})
    assert env.observation_space == observation_space(8, 12, 1, True, True)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*infinity.*")
        check_env(env, skip_render_check=True)
    observations = random_episodes(env, 2)[0]
    assert all(observation in env.observation_space for observation in observations)
    env.reset(seed=5)
    env.step(DO_NOTHING)
    copy = pickle.loads(pickle.dumps(env))
    for action in (DO_NOTHING, DO_NOTHING):
        a, b = env.step(action)[0], copy.step(action)[0]
        assert all(np.array_equal(a[key], b[key]) for key in a)


@pytest.mark.parametrize("extensions", [
    RECORDED,
    {**RECORDED, "latency_steps": 2, "hidden_neurons": 2, "background_rate": 0.05},
], ids=["recorded", "recorded-latency-hidden-background"])  # fmt: skip
def test_the_vector_env_equals_single_envs_with_autoresets(extensions):
    """Three episodes with their autoresets, then a reset to a given context: each
    environment's draws (context, recording, background) come from its own generator in
    the single environment's order."""
    num_envs = 4
    kwargs = {**SHORT, "extensions": extensions}
    batched = NeuronControlVectorEnv(num_envs=num_envs, **kwargs)
    sync = SyncVectorEnv([lambda: NeuronControlEnv(**kwargs) for _ in range(num_envs)],
                         autoreset_mode=AutoresetMode.NEXT_STEP)  # fmt: skip
    assert batched.single_observation_space == sync.single_observation_space
    rng = np.random.default_rng(13)
    masks, hidden_spikes = set(), 0
    for reset in ({"seed": 7}, {"options": {"context": 1}}):
        obs_a, info_a = batched.reset(**reset)
        obs_b, _ = sync.reset(**reset)
        for step in range(3 * 13 + 2):
            assert set(obs_a) == set(obs_b) and RECORDED_KEY in obs_a
            for key in obs_a:
                np.testing.assert_array_equal(obs_a[key], obs_b[key], err_msg=f"{step} {key}")
            assert obs_a in batched.observation_space
            masks.update(map(tuple, obs_a[RECORDED_KEY]))
            actions = np.array([rng.choice(np.flatnonzero(m)) - 1 for m in info_a["action_mask"]])
            obs_a, info_a, obs_b = step_alike(batched, sync, actions)
            present = info_a["_spikes"]
            if not present.any():
                continue
            spikes, mask = info_a["spikes"][present], obs_a[RECORDED_KEY][present]
            np.testing.assert_array_equal(obs_a[SPIKES_KEY][present], spikes * mask)
            hidden_spikes += int((spikes & (mask == 0)).sum())
    assert len(masks) > 4 and hidden_spikes > 0


# -- the flat codec


def test_the_flat_layout_ends_with_the_recorded_mask():
    """Spikes-only's 3k + 3N + 2 entries (the spikes as recorded in the first k), the
    actions in flight, then k entries of the mask (bounds 0 and 1); the Dict has int8
    ``recorded``."""
    k, base = 8, 3 * 8 + 3 * 12 + 2
    for latency in (0, 1):
        extensions = {**RECORDED, "latency_steps": latency}
        env = NeuronControlEnv(**SHORT, extensions=extensions)
        codec = observation_for(env, flatten=True)
        without = observation_for(NeuronControlEnv(**SHORT, extensions={**SPIKES,
                                  "latency_steps": latency}), flatten=True)  # fmt: skip
        assert codec.size == without.size + k == base + latency * (k + 1) + k
        np.testing.assert_array_equal(codec.space.low[-k:], 0.0)
        np.testing.assert_array_equal(codec.space.high[-k:], 1.0)
        np.testing.assert_array_equal(codec.space.low[:-k], without.space.low)
        np.testing.assert_array_equal(codec.space.high[:-k], without.space.high)
        for observation in random_episodes(env, 8)[0]:
            flat = codec(observation)
            assert flat in codec.space
            np.testing.assert_array_equal(flat[-k:], observation[RECORDED_KEY])
            np.testing.assert_array_equal(flat[:k], observation[SPIKES_KEY])
            bare = {key: value for key, value in observation.items() if key != RECORDED_KEY}
            np.testing.assert_array_equal(flat[:-k], without(bare))
    as_dict = FlatEnv(NeuronControlEnv(**SHORT, extensions=RECORDED), flatten=False)
    observation, _ = as_dict.reset(seed=0)
    assert observation[RECORDED_KEY].dtype == np.int8 and observation in as_dict.observation_space
    assert observation[RECORDED_KEY].sum() == 3


def test_the_flat_vector_env_equals_the_flat_env_with_autoresets():
    kwargs = {**SHORT, "extensions": {**RECORDED, "latency_steps": 1}}
    assert_flat_vector_env_steps_as_singles(FlatNeuronControlVectorEnv, FlatNeuronControlEnv,
                                            kwargs, 2 * 13 + 1)  # fmt: skip


# -- bad inputs


@pytest.mark.parametrize(("value", "error", "message"), [
    (0, ConfigError, r"recorded_neurons must be >= 1 \(the target is always recorded\)"),
    (-3, ConfigError, "recorded_neurons must be >= 1"),
    (2.5, ConfigTypeError, "recorded_neurons must be an integer or None, got 2.5"),
    ("3", ConfigTypeError, "recorded_neurons must be an integer or None, got '3'"),
    (True, ConfigTypeError, "recorded_neurons must be an integer or None, got True"),
])  # fmt: skip
def test_a_bad_count_is_one_named_line(value, error, message):
    with pytest.raises(error, match=message) as caught:
        Extensions(**SPIKES, recorded_neurons=value)
    assert "\n" not in str(caught.value) and caught.value.path == ("recorded_neurons",)


def test_a_count_needs_spikes_and_at_most_the_observed_neurons():
    with pytest.raises(ConfigError, match="recorded_neurons records spikes: it needs "
                       "sensing='spikes', got sensing='potentials'"):  # fmt: skip
        Extensions(recorded_neurons=3)
    assert Extensions(**SPIKES, recorded_neurons=np.int64(2)).recorded_neurons == 2
    for make in (NeuronControlEnv, lambda **kw: NeuronControlVectorEnv(2, **kw)):
        with pytest.raises(ConfigError, match="must be at most the 8 observed neurons, got 9"):
            make(**SHORT, extensions={**SPIKES, "recorded_neurons": 9})
        with pytest.raises(ConfigError, match="must be at most the 6 observed neurons, got 7"):
            make(**SHORT, extensions={**SPIKES, "recorded_neurons": 7, "hidden_neurons": 2})


def test_the_cli_refuses_a_bad_count_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "smoke", "--extensions.sensing", "spikes", "--extensions.recorded-neurons",
              "0", "--run-dir", str(tmp_path / "run")])  # fmt: skip
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert "--extensions.recorded-neurons must be >= 1" in error and len(error.splitlines()) == 1
    assert not (tmp_path / "run").exists()


# -- who plays it


def test_identify_and_plan_refuses_in_one_line_and_the_oracle_plays_as_before():
    test_set = ContextSet.generate(4, n_neurons=8, seed=11)
    env = NeuronControlEnv(contexts=test_set, extensions=RECORDED)
    extensions = env.extensions
    refusal = first_decision_refusal(env, lambda: IdentifyAndPlan(
        test_set.params, named_composition(extensions, 8), extensions=extensions))  # fmt: skip
    assert refusal is not None and refusal.endswith("it cannot with recorded_neurons")
    whole = evaluate_policy(test_set, OraclePlanner(test_set), extensions=Extensions(**SPIKES))
    part = evaluate_policy(test_set, OraclePlanner(test_set), extensions=extensions)
    np.testing.assert_array_equal(whole.actions, part.actions)
    np.testing.assert_array_equal(whole.rewards, part.rewards)


def test_an_agent_reads_the_recorded_spikes_at_threshold():
    """run_episodes stores V_th where a recorded neuron spiked, V_r elsewhere (an
    unrecorded neuron's spike included); a bare policy reads the same."""
    contexts = ContextSet.generate(6, n_neurons=8, seed=3)
    seen, recorded, random = [], [], RandomLegal(seed=1)

    def policy(observations, action_mask):
        seen.append(observations["voltage"].copy())
        recorded.append(observations[RECORDED_KEY].copy())
        return random.act_batch(observations, {"action_mask": action_mask})

    episodes = evaluate_policy(contexts, policy, extensions=Extensions(**RECORDED), seed=2)
    mask = np.stack(recorded, axis=1)  # [S, N, k], fixed within each episode
    assert (mask == mask[:, :1]).all() and (mask.sum(axis=2) == 3).all()
    shown = episodes.spikes & (mask[:, 0:1] == 1)
    assert shown.any() and (episodes.spikes & ~shown).any()
    np.testing.assert_array_equal(
        episodes.voltage[:, 1:], np.where(shown, np.float32(THRESHOLD), np.float32(REST))
    )
    np.testing.assert_array_equal(np.stack(seen, axis=1), episodes.voltage[:, :-1])


def test_a_learner_trains_on_a_recorded_subset(tmp_path):
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the machine's cores are shared
    try:
        config = SMOKE.with_changes({
            "env.extensions.sensing": "spikes", "env.extensions.recorded_neurons": 3,
            "total_env_steps": 6 * 8 * 20, "eval_every_episodes": 16,
            "checkpoint_every_episodes": 16,
        })  # fmt: skip
        rows = train(config, tmp_path / "run")
        assert rows[-1]["updates"] > 0 and all(math.isfinite(row["loss"]) for row in rows[1:])
        # The trained network and its compiled policy play the environment it trained on.
        env = config.env
        contexts = ContextSet.generate(3, env.n_neurons, env.episode_length, seed=5)
        for compiled in (False, True):
            controller = load_controller(tmp_path / "run", compiled=compiled)
            episodes = evaluate_policy(contexts, controller, extensions=env.extensions)
            assert ((episodes.returns >= 0) & (episodes.returns <= 1)).all()
    finally:
        torch.set_num_threads(threads)
