"""The training-free controllers: the oracle planner, identification, identify-and-plan."""

from __future__ import annotations

import csv

import gymnasium as gym
import numpy as np
import pytest

import spikectl
from spikectl import IdentifyAndPlan, NeuronParams, make_context, make_splits, plan_episode
from spikectl.cli import main
from spikectl.planning import ConnectivityEstimate, ObservedState
from spikectl.planning.baselines import run_baselines
from spikectl.rollout import evaluate_policy


@pytest.fixture(scope="module")
def splits():
    return make_splits(20, 20, seed=0)


def _pattern(length: int, spikes: list[int]) -> np.ndarray:
    pattern = np.zeros(length, dtype=bool)
    pattern[spikes] = True
    return pattern


# -- the oracle planner on hand-built networks


def test_planner_hits_a_pattern_through_one_synapse():
    # 0 -> 1 excitatory; 1 must spike at 1, 7 and 13: stimulate 0 one step before each
    # (0 is ready again after 5 steps).
    context = make_context(np.array([[0, 1], [0, 0]]), target=1,
                           pattern=_pattern(20, [1, 7, 13]))  # fmt: skip
    actions, ret = plan_episode(context)
    assert ret == pytest.approx(1.0, abs=1e-12)
    assert np.flatnonzero(actions >= 0).tolist() == [0, 6, 12]
    assert set(actions.tolist()) <= {-1, 0}  # never the target


def test_planner_uses_a_two_synapse_chain_and_a_second_input():
    # 0 -> 1 -> 2 and 3 -> 2, with 1 hidden (not stimulable); the target 2 must spike
    # at steps 2 and 4, two steps apart: 3 releases at most every 5 steps, so one of
    # the two spikes must come through the chain from 0 (stimulated two steps early).
    weights = np.zeros((4, 4), dtype=int)
    weights[0, 1] = weights[1, 2] = weights[3, 2] = 1
    context = make_context(weights, target=2, pattern=_pattern(12, [2, 4]),
                           hidden=np.array([1]))  # fmt: skip
    actions, ret = plan_episode(context, width=16)
    assert ret == pytest.approx(1.0, abs=1e-12)
    assert 0 in actions and 3 in actions and 1 not in actions


def test_planned_return_is_the_environment_return(splits):
    train, _ = splits
    for context in train[:5]:
        actions, ret = plan_episode(context, width=32)
        env = spikectl.NeuronControlEnv(contexts=train[:5])
        env.reset(seed=0, options={"context": context})
        total = sum(env.step(int(a))[1] for a in actions)
        assert total == pytest.approx(ret, abs=1e-12)
        assert ret <= 1.0 + 1e-12


def test_oracle_planner_reaches_the_headroom_on_training_networks(splits):
    train, _ = splits
    returns = [plan_episode(context)[1] for context in train[:10]]
    assert np.mean(returns) >= 0.99


def test_plan_episode_rejects_bad_input(splits):
    with pytest.raises(TypeError, match="Context"):
        plan_episode("context")
    with pytest.raises(ValueError, match="width"):
        plan_episode(splits[0][0], width=0)
    with pytest.raises(TypeError, match="NeuronParams"):
        plan_episode(splits[0][0], params={"dt_ms": 1})


# -- identification


def _identify(weights: np.ndarray, actions: list[int]) -> ConnectivityEstimate:
    params = NeuronParams()
    voltages, _ = spikectl.simulate(weights, np.array(actions), params)
    tracker = ObservedState(weights.shape[0], params, spike_margin_mV=0.0)
    estimate = ConnectivityEstimate(weights.shape[0], residual_sd=0.01)
    for t, action in enumerate(actions):
        estimate.add(*tracker.observe(voltages[t].astype(np.float32), action))
    return estimate


def test_identification_recovers_the_rows_of_every_released_neuron_exactly():
    # A feed-forward network: stimulating 0, 1, 2 and 3 in turn releases each of 0..4
    # at least once (0 makes 1 and 2 fire together, which is ambiguous for 3's
    # column until 1 and 2 are stimulated alone). Neuron 5 has no input and is never
    # stimulated, so it never releases.
    weights = np.zeros((6, 6), dtype=int)
    weights[0, [1, 2]] = 1
    weights[1, [3, 4]] = 1
    weights[2, 3] = -1
    weights[3, 4] = 1
    weights[5, 4] = 1
    actions = [-1] * 28
    for step, neuron in ((0, 0), (7, 1), (14, 2), (21, 3)):
        actions[step] = neuron
    estimate = _identify(weights, actions)
    signs, known = estimate.weights(known_sd=0.25)
    mean, sd = estimate.posterior()
    released = [0, 1, 2, 3, 4]
    assert known[released].all()
    assert np.array_equal(signs[released], weights[released])
    assert np.abs(mean[released] - weights[released]).max() < 1e-3
    # neuron 5 never released: its outgoing weights keep the prior's uncertainty
    assert not known[5, :5].any()
    assert (sd[5, :5] > 0.3).all()


def test_every_entry_identification_calls_known_is_exact(splits):
    train, _ = splits
    policy = IdentifyAndPlan().vector_policy(10)
    evaluate_policy(train[:10], policy)
    for context, copy in zip(train[:10], policy.copies, strict=True):
        signs, known = copy.estimate.weights(copy.known_sd)
        assert known.sum() > 8  # it learned something
        assert np.array_equal(signs[known], context.weights[known])


# -- identify-and-plan


def test_identify_and_plan_beats_the_reference_policies(splits):
    train, _ = splits
    returns = evaluate_policy(train, IdentifyAndPlan().vector_policy(len(train))).returns
    assert returns.mean() > 0.75  # random ~0.51, do nothing 0.5
    assert returns.min() >= 0.0 and returns.max() <= 1.0 + 1e-12


@pytest.mark.parametrize(
    "env_id",
    ["spikectl/NeuronControl-v0", "spikectl/NeuronControlPartial-v0",
     pytest.param("spikectl/NeuronControlRealistic-v0", marks=pytest.mark.slow)],
)  # fmt: skip
def test_identify_and_plan_never_takes_an_illegal_action(env_id):
    # The environment raises on an illegal action; the Realistic variant switches every
    # extension on (noise, hidden, stochastic release, heterogeneity, background).
    env = gym.make(env_id, n_train=4, n_test=4)
    noise = env.unwrapped.extensions.observation_noise_mV
    policy = IdentifyAndPlan(noise_mV=noise, width=8)
    for episode in range(3):
        observation, info = env.reset(seed=episode)
        policy.reset()
        terminated = False
        while not terminated:
            action = policy.act(observation, info)
            assert info["action_mask"][action + 1]
            observation, _, terminated, _, info = env.step(action)


def test_identify_and_plan_is_deterministic(splits):
    train, _ = splits
    first = evaluate_policy(train[:6], IdentifyAndPlan().vector_policy(6))
    second = evaluate_policy(train[:6], IdentifyAndPlan().vector_policy(6))
    assert np.array_equal(first.actions, second.actions)
    assert np.array_equal(first.returns, second.returns)


def test_identify_and_plan_rejects_bad_settings_and_mid_episode_starts(splits):
    with pytest.raises(ValueError, match="width"):
        IdentifyAndPlan(width=0)
    with pytest.raises(ValueError, match="horizon"):
        IdentifyAndPlan(horizon=0)
    with pytest.raises(ValueError, match="noise_mV"):
        IdentifyAndPlan(noise_mV=-1.0)
    with pytest.raises(TypeError, match="NeuronParams"):
        IdentifyAndPlan(params="paper")
    env = spikectl.NeuronControlEnv(contexts=splits[0][:2])
    observation, info = env.reset(seed=0)
    observation, *_, info = env.step(-1)
    with pytest.raises(ValueError, match="first step"):
        IdentifyAndPlan().act(observation, info)


# -- the table and the CLI


def test_run_baselines_orders_the_controllers(splits):
    _, test = splits
    results = run_baselines(test[:6], random_seeds=2, oracle_width=32)
    returns = results.returns
    assert np.allclose(returns["do_nothing"], 0.5)
    assert np.allclose(returns["witness"], 1.0)
    assert (returns["oracle"] >= returns["do_nothing"] - 1e-12).all()
    assert returns["oracle"].mean() >= returns["identify_and_plan"].mean()
    assert results.random_seed_means.shape == (2,)
    assert "identify-and-plan" in results.table()


def test_cli_baselines_prints_the_table_and_writes_the_csv(tmp_path, capsys, splits):
    path = splits[1][:4].save(tmp_path / "four.npz")
    out = tmp_path / "table.csv"
    main(["baselines", "--contexts", str(path), "--out", str(out), "--random-seeds", "2",
          "--oracle-width", "16"])  # fmt: skip
    printed = capsys.readouterr().out
    for name in ("do-nothing", "random", "identify-and-plan", "oracle", "witness"):
        assert name in printed
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 4
    assert [float(row["witness"]) for row in rows] == pytest.approx([1.0] * 4)
    with pytest.raises(SystemExit) as error:
        main(["baselines", "--env", "spikectl/NoSuchEnv-v0", "--out", str(out)])
    assert error.value.code == 2
    assert "unknown environment id" in capsys.readouterr().err
