"""The training-free controllers: the oracle planner, identification, identify-and-plan."""

from __future__ import annotations

import csv

import gymnasium as gym
import numpy as np
import pytest
from conftest import play_legally, spike_pattern

import spikectl
from spikectl import IdentifyAndPlan, NeuronParams, make_context, plan_episode
from spikectl.cli import main
from spikectl.contexts import NeuronSetup
from spikectl.envs.controller import batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.planning import (
    Composition,
    ConnectivityEstimate,
    DecisionSettings,
    DiscreteConnectivityEstimate,
    EstimatorSettings,
    ObservationSettings,
    ObservedState,
    ProberSettings,
    named_composition,
)
from spikectl.planning.baselines import run_baselines

# -- the oracle planner on hand-built networks


def test_planner_hits_a_pattern_through_one_synapse():
    # 0 -> 1 excitatory; 1 must spike at 1, 7 and 13: stimulate 0 one step before each
    # (0 is ready again after 5 steps).
    context = make_context(np.array([[0, 1], [0, 0]]), target=1,
                           pattern=spike_pattern(20, [1, 7, 13]))  # fmt: skip
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
    context = make_context(weights, target=2, pattern=spike_pattern(12, [2, 4]),
                           neurons=NeuronSetup(hidden=np.array([1])))  # fmt: skip
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


def _identify(weights: np.ndarray, actions: list[int], estimator=ConnectivityEstimate):
    params = NeuronParams()
    voltages, _ = spikectl.simulate(weights, np.array(actions), params)
    tracker = ObservedState(weights.shape[0], params, spike_margin_mV=0.0)
    estimate = estimator(weights.shape[0], residual_sd=0.01)
    for t, action in enumerate(actions):
        estimate.add(*tracker.observe(voltages[t].astype(np.float32), action))
    return estimate


def feed_forward_probe() -> tuple[np.ndarray, list[int]]:
    """A 6-neuron feed-forward network and 28 actions stimulating 0, 1, 2 and 3 in turn."""
    weights = np.zeros((6, 6), dtype=int)
    weights[0, [1, 2]] = 1
    weights[1, [3, 4]] = 1
    weights[2, 3] = -1
    weights[3, 4] = 1
    weights[5, 4] = 1
    actions = [-1] * 28
    for step, neuron in ((0, 0), (7, 1), (14, 2), (21, 3)):
        actions[step] = neuron
    return weights, actions


@pytest.mark.parametrize("estimator", [ConnectivityEstimate, DiscreteConnectivityEstimate])
def test_identification_recovers_the_rows_of_every_released_neuron_exactly(estimator):
    # A feed-forward network: stimulating 0, 1, 2 and 3 in turn releases each of 0..4
    # at least once (0 makes 1 and 2 fire together, which is ambiguous for 3's
    # column until 1 and 2 are stimulated alone). Neuron 5 has no input and is never
    # stimulated, so it never releases.
    weights, actions = feed_forward_probe()
    estimate = _identify(weights, actions, estimator)
    signs, known = estimate.weights(known_sd=0.25)
    mean, sd = estimate.posterior()
    released = [0, 1, 2, 3, 4]
    assert known[released].all()
    assert np.array_equal(signs[released], weights[released])
    # (the discrete posterior keeps a 1 % outlier share per observation)
    tolerance = 1e-3 if estimator is ConnectivityEstimate else 1e-2
    assert np.abs(mean[released] - weights[released]).max() < tolerance
    # neuron 5 never released: its outgoing weights keep the prior's uncertainty
    assert not known[5, :5].any()
    assert (sd[5, :5] > 0.3).all()


def test_discrete_identification_separates_neurons_that_always_release_together():
    # 0 -> 1 and 0 -> 2 excitatory, 1 -> 3 excitatory, 2 -> 3 none: 1 and 2 only ever
    # release together, and 3 receives +20 mV. Neither posterior can tell whose
    # synapse it is (equal priors: d = 2 and d = 1); the discrete one knows that
    # exactly one of the two is +1 and the other 0 (the hypotheses left are (1, 0)
    # and (0, 1)), and that 0 -> 3 is 0.
    weights = np.zeros((4, 4), dtype=int)
    weights[0, [1, 2]] = 1
    weights[1, 3] = 1
    estimate = _identify(weights, [0] + [-1] * 4, DiscreteConnectivityEstimate)
    mean, sd = estimate.posterior()
    assert mean[1, 3] + mean[2, 3] == pytest.approx(1.0, abs=1e-3)
    assert mean[1, 3] == pytest.approx(0.5, abs=1e-3) and sd[1, 3] > 0.25
    assert mean[0, 3] == pytest.approx(0.0, abs=1e-3) and sd[0, 3] < 0.05


def test_discrete_identification_refuses_large_networks():
    with pytest.raises(ValueError, match="over the limit"):
        DiscreteConnectivityEstimate(16, 0.01)


def test_every_entry_identification_calls_known_is_exact(splits):
    train, _ = splits
    policy = batched(IdentifyAndPlan())
    evaluate_policy(train[:10], policy)
    for context, copy in zip(train[:10], policy.copies, strict=True):
        signs, known = copy.estimate.weights(copy.known_sd)
        assert known.sum() > 8  # it learned something
        assert np.array_equal(signs[known], context.weights[known])


def test_sampled_hypotheses_keep_known_entries_and_follow_the_uniforms():
    weights, actions = feed_forward_probe()
    estimate = _identify(weights, actions)
    signs, known = estimate.weights(known_sd=0.25)
    k = 3
    never = estimate.sample(0.25, np.full((k, 6, 6), 0.999), np.zeros((k, 6)))
    always = estimate.sample(0.25, np.zeros((k, 6, 6)), np.full((k, 6), 0.999))
    for hypotheses in (never, always):
        assert hypotheses.shape == (k, 6, 6) and hypotheses.dtype == np.int8
        assert (hypotheses[:, known] == signs[known]).all()
    assert (never[:, ~known] == 0).all()
    # every unknown entry is drawn as a connection; row 5 never released, so its sign
    # is drawn (inhibitory at u = 0.999); rows with a known sign keep it (Dale's law)
    unknown_row5 = ~known[5]
    assert unknown_row5.any() and (always[:, 5, unknown_row5] == -1).all()
    assert (np.diagonal(always, axis1=1, axis2=2) == 0).all()  # prior says: never


def test_beam_search_on_identical_hypotheses_is_the_single_network_search(splits):
    from dataclasses import replace

    from spikectl.neuron.simulator import SimulatorState
    from spikectl.planning import beam_search, model_of_context

    for context in splits[0][:4]:
        model = model_of_context(context)
        start = SimulatorState.at_rest(1, context.n_neurons, model.params)
        single = beam_search(model, start, context.pattern, 0, 16)
        tripled = replace(model, weights=np.ascontiguousarray(np.repeat(model.weights, 3, 0)))
        planned = beam_search(tripled, start, context.pattern, 0, 16)
        assert np.array_equal(single.actions, planned.actions)
        assert np.allclose(single.rewards, planned.rewards, atol=1e-12)


def test_beam_search_ranks_by_the_mean_over_hypotheses():
    # Two hypotheses about 0 -> 1 and 2 -> 1: under the first only 0 excites the target,
    # under the second only 2 does; stimulating 0 at step 0 hits the wanted spike at
    # step 1 under one of them (mean reward half of the spike's), as does 2.
    from spikectl.neuron.simulator import SimulatorState
    from spikectl.planning import PlanningModel, beam_search

    first = np.zeros((3, 3), dtype=np.int8)
    first[0, 1] = 1
    second = np.zeros((3, 3), dtype=np.int8)
    second[2, 1] = 1
    params = NeuronParams()
    model = PlanningModel(np.stack([first, second]), 1, np.array([-1, 0, 2]), params)
    pattern = spike_pattern(4, [1])
    plan = beam_search(model, SimulatorState.at_rest(1, 3, params), pattern, 0, 8)
    assert plan.actions[0] in (0, 2)
    assert plan.rewards[1] == pytest.approx(0.5 / 2)  # hit under one of two hypotheses


# -- identify-and-plan


def test_identify_and_plan_beats_the_reference_policies(splits):
    train, _ = splits
    returns = evaluate_policy(train, batched(IdentifyAndPlan())).returns
    assert returns.mean() > 0.75  # random ~0.51, do nothing 0.5
    assert returns.min() >= 0.0 and returns.max() <= 1.0 + 1e-12


EXTENSION_CASES = {
    "noise 1 mV": {"observation_noise_mV": 1.0},
    "noise 4 mV": {"observation_noise_mV": 4.0},
    "hidden 0.25": {"hidden_fraction": 0.25},
    "stochastic release": {"stochastic_release": True},
    "background": {"background_rate": 0.05},
    "heterogeneous": {"threshold_spread": 0.2, "time_constant_spread": 0.2,
                      "synaptic_spread": 0.2},
    "bleaching": {"bleaching_time_constant_steps": 30.0},
    "target action": {"allow_target_action": True},
}  # fmt: skip


NARROW = Composition("width8", decision=DecisionSettings(width=8))


@pytest.mark.parametrize(
    ("env_id", "extensions"),
    [("spikectl/NeuronControl-v0", None), ("spikectl/NeuronControlPartial-v0", None),
     *[pytest.param("spikectl/NeuronControl-v0", value, id=key)
       for key, value in EXTENSION_CASES.items()],
     pytest.param("spikectl/NeuronControlRealistic-v0", None, marks=pytest.mark.slow)],
)  # fmt: skip
def test_identify_and_plan_never_takes_an_illegal_action(env_id, extensions):
    # The environment raises on an illegal action; each extension alone must degrade
    # the policy, not crash it, and the Realistic variant switches every one on.
    kwargs = {} if extensions is None else {"extensions": extensions}
    env = gym.make(env_id, contexts={"n_train": 4, "n_test": 4}, **kwargs)
    told = env.unwrapped.extensions
    play_legally(env, IdentifyAndPlan(composition=NARROW, extensions=told), range(3))
    named = named_composition(told, env.unwrapped.contexts.n_observed)
    play_legally(env, IdentifyAndPlan(composition=named.with_width(8), extensions=told), range(3))


def test_identify_and_plan_is_deterministic(splits):
    train, _ = splits
    first = evaluate_policy(train[:6], batched(IdentifyAndPlan()))
    second = evaluate_policy(train[:6], batched(IdentifyAndPlan()))
    assert np.array_equal(first.actions, second.actions)
    assert np.array_equal(first.returns, second.returns)


def test_identify_and_plan_rejects_bad_settings_and_mid_episode_starts(splits):
    with pytest.raises(ValueError, match="width"):
        DecisionSettings(width=0)
    with pytest.raises(ValueError, match="horizon"):
        DecisionSettings(horizon=0)
    with pytest.raises(ValueError, match="known_sd"):
        EstimatorSettings(known_sd=0.0)
    with pytest.raises(ValueError, match="seed"):
        IdentifyAndPlan(seed=-1)
    with pytest.raises(ValueError, match="unknown estimator 'exact'; this spikectl has gaussian"):
        EstimatorSettings("exact")
    with pytest.raises(ValueError, match="spike_margin_sd"):
        ObservationSettings(spike_margin_sd=-1.0)
    with pytest.raises(ValueError, match="unknown_entry_bonus"):
        ProberSettings(unknown_entry_bonus=-1.0)
    with pytest.raises(TypeError, match="NeuronParams"):
        IdentifyAndPlan(params="paper")
    with pytest.raises(TypeError, match="composition must be a Composition"):
        IdentifyAndPlan(composition={"width": 8})
    with pytest.raises(TypeError, match="decision must be a DecisionSettings"):
        Composition(decision=EstimatorSettings())
    with pytest.raises(ValueError, match="name"):
        Composition("")
    with pytest.raises(TypeError, match="extensions must be an Extensions"):
        IdentifyAndPlan(extensions={"stochastic_release": True})
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
    with pytest.raises(SystemExit) as error:
        main(["baselines", "--contexts", str(path), "--hidden-fraction", "0.25"])
    assert error.value.code == 2
    assert "--hidden-fraction applies to generated sets" in capsys.readouterr().err


def test_cli_baselines_measurement_noise_override(tmp_path, capsys, splits):
    path = splits[1][:3].save(tmp_path / "three.npz")
    out = tmp_path / "noisy.csv"
    main(["baselines", "--contexts", str(path), "--out", str(out), "--random-seeds", "1",
          "--oracle-width", "8", "--identify-width", "8",
          "--observation-noise-mV", "4"])  # fmt: skip
    printed = capsys.readouterr().out
    assert "observation_noise_mV=4.0" in printed
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    # noise touches observations only: the open-loop oracle and witness are unchanged
    assert [float(row["witness"]) for row in rows] == pytest.approx([1.0] * 3)
