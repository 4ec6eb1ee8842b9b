"""The opsin-aware planner (spikectl/planning/lit_search.py): the oracle through ChR2."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.contexts import Context
from spikectl.envs.controller import DoNothing
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.opsin import OpsinActuator
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import SimulatorState
from spikectl.planning.lit_search import (
    Occupancies,
    lit_beam_search,
    lit_spikes,
    lit_state_after,
    planned_light,
)
from spikectl.planning.oracle import OraclePlanner, model_of_context, plan_episode

PARAMS = NeuronParams()
CHR2 = Extensions(actuator="chr2")


def opsin_of(n: int, irradiance: float = 5.0) -> OpsinActuator:
    return OpsinActuator(1, n, irradiance, PARAMS.dt_ms, PARAMS.capacitance_pF)


def env_raster(contexts, index: int, actions, extensions) -> np.ndarray:
    env = NeuronControlEnv(contexts=contexts, extensions=extensions)
    env.reset(options={"context": index})
    return np.array([env.step(int(a))[4]["spikes"] for a in actions])


def test_planned_light_is_none_for_the_pulse_and_the_irradiance_for_chr2():
    assert planned_light(None) is None
    assert planned_light(Extensions()) is None
    assert planned_light(Extensions(actuator="chr2", light_irradiance_mW_per_mm2=2.5)) == 2.5


def test_the_planners_step_is_the_environments_on_test_networks():
    contexts = load_split("paper", "test")[:3]
    rng = np.random.default_rng(0)
    for index, context in enumerate(contexts):
        model = model_of_context(context, contexts.params)
        actions = rng.choice(model.actions, size=context.episode_length)
        expected = env_raster(contexts, index, actions, CHR2)
        np.testing.assert_array_equal(lit_spikes(model, opsin_of(8), actions), expected)


def test_one_light_pulse_by_hand_spikes_at_the_next_step_and_three_later():
    # tests/test_opsin.py's pulse (Cleo's trace): neuron 0 lit at step 2 spikes at 3, 6, 10.
    pattern = np.zeros(12, dtype=bool)
    pattern[1] = True
    context = Context(np.zeros((3, 3), dtype=np.int8), 1, pattern)
    model = model_of_context(context, PARAMS)
    raster = lit_spikes(model, opsin_of(3), np.array([-1, -1, 0] + [-1] * 9))
    assert np.flatnonzero(raster[:, 0]).tolist() == [3, 6, 10]
    assert not raster[:, 1:].any()


def test_state_after_steps_the_occupancies_as_the_actuator_does():
    context = load_split("paper", "test")[0]
    model = model_of_context(context, PARAMS)
    start = SimulatorState.at_rest(1, 8, PARAMS), Occupancies.at_rest(1, 8)
    state, occupancies = lit_state_after(model, opsin_of(8), *start, np.array([2, -1, 5]))
    actuator = opsin_of(8)
    for lit in (2, -1, 5):  # the occupancies depend on the light alone
        actuator.illuminate(np.full((1, 8), -70.0), np.array([[lit]]), np.empty((1, 1, 8)))
    np.testing.assert_array_equal(occupancies.o1, actuator.o1)
    np.testing.assert_array_equal(occupancies.c1, actuator.c1)
    assert start[1].c1.min() == 1.0  # the start is left as it was


def test_a_wanted_spike_through_one_excitatory_synapse_is_met_by_light_two_steps_before():
    # 0 -> 1 excitatory; the target (1) wanted at step 6 only: lit at 4, neuron 0 spikes at
    # 5 and 8, the target fires at 6 (and, were that synapse strong enough, at 9).
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 1] = 1
    pattern = np.zeros(20, dtype=bool)
    pattern[6] = True
    context = Context(weights, 1, pattern)
    actions, ret = plan_episode(context, PARAMS, width=16, light_mW_per_mm2=5.0)
    raster = lit_spikes(model_of_context(context, PARAMS), opsin_of(3), actions)
    assert raster[6, 1]
    reward_if_spike, reward_if_silent = 0.5, 0.5 / 19
    expected = sum(reward_if_spike if pattern[t] == raster[t, 1] and pattern[t]
                   else reward_if_silent if pattern[t] == raster[t, 1] else 0.0
                   for t in range(20))  # fmt: skip
    assert ret == pytest.approx(expected)
    assert np.flatnonzero(actions >= 0).min() <= 4  # the light comes >= 2 steps ahead


def test_the_oracle_plays_its_planned_return_and_beats_the_pulse_oracle_under_chr2():
    contexts = load_split("paper", "test")[:4]
    aware = OraclePlanner(contexts, contexts.params, 32, light_mW_per_mm2=5.0)
    played = evaluate_policy(contexts, aware, extensions=CHR2, seed=0).returns
    planned = [plan_episode(c, contexts.params, 32, light_mW_per_mm2=5.0)[1] for c in contexts]
    np.testing.assert_allclose(played, planned, rtol=0, atol=1e-12)
    pulse = evaluate_policy(contexts, OraclePlanner(contexts, contexts.params, 32),
                            extensions=CHR2, seed=0).returns  # fmt: skip
    nothing = evaluate_policy(contexts, DoNothing(), extensions=CHR2, seed=0).returns
    assert played.mean() > pulse.mean() + 0.2
    assert played.mean() > nothing.mean() + 0.3


def test_a_latency_and_the_opsin_together_replay_exactly():
    contexts = load_split("paper", "test")[:2]
    both = Extensions(actuator="chr2", latency_steps=2)
    aware = OraclePlanner(contexts, contexts.params, 16, light_mW_per_mm2=5.0)
    played = evaluate_policy(contexts, aware, extensions=both, seed=0).returns
    planned = [plan_episode(c, contexts.params, 16, latency_steps=2, light_mW_per_mm2=5.0)[1]
               for c in contexts]  # fmt: skip
    np.testing.assert_allclose(played, planned, rtol=0, atol=1e-12)
    assert (aware.plan(0, 2)[-2:] == -1).all()  # the last two never land


def test_the_search_keeps_hypotheses_and_refuses_bad_settings():
    context = load_split("paper", "test")[0]
    model = model_of_context(context, PARAMS)
    start = SimulatorState.at_rest(1, 8, PARAMS), Occupancies.at_rest(1, 8)
    one = lit_beam_search(model, opsin_of(8), start, context.pattern, 0, 8)
    # The same network twice as two hypotheses: the same plan and the same mean rewards.
    twice = type(model)(np.repeat(model.weights, 2, axis=0), model.target, model.actions,
                        model.params)  # fmt: skip
    start2 = SimulatorState.at_rest(2, 8, PARAMS), Occupancies.at_rest(2, 8)
    two = lit_beam_search(twice, opsin_of(8), start2, context.pattern, 0, 8)
    np.testing.assert_array_equal(one.actions, two.actions)
    np.testing.assert_allclose(one.rewards, two.rewards)
    with pytest.raises(ValueError, match="width must be >= 1"):
        lit_beam_search(model, opsin_of(8), start, context.pattern, 0, 0)
    with pytest.raises(ValueError, match="start_step"):
        lit_beam_search(model, opsin_of(8), start, context.pattern, 60, 4)


def test_identify_and_plan_reads_each_step_with_the_lights_current():
    # The residual of every observed neuron is its synaptic input alone: released
    # presynaptic neurons' weights, as under the pulse (the opsin's drive subtracted).
    from spikectl.planning.named import named_composition
    from spikectl.planning.policy import IdentifyAndPlan

    contexts = load_split("paper", "test")[:2]
    rng = np.random.default_rng(1)
    for index, context in enumerate(contexts):
        policy = IdentifyAndPlan(contexts.params, named_composition(CHR2, 8), extensions=CHR2)
        reader = policy.observation.reader(8)
        assert reader.opsin is not None
        env = NeuronControlEnv(contexts=contexts, extensions=CHR2)
        env.reset(options={"context": index})
        model = model_of_context(context, PARAMS)
        lights = 0
        for _ in range(context.episode_length):
            action = int(rng.choice(model.actions))
            observation = env.step(action)[0]
            released, residual, observed = reader.read(observation["voltage"], action, None)
            expected = context.weights.T.astype(float) @ released
            np.testing.assert_allclose(residual[observed], expected[observed], atol=1e-4)
            lights += action >= 0
        assert lights > 30 and reader.opsin.o1.max() > 0.1


def test_identify_and_plan_plans_the_light_and_the_pulse_is_unchanged():
    from spikectl.planning.named import named_composition
    from spikectl.planning.policy import IdentifyAndPlan

    contexts = load_split("paper", "test")[:4]
    aware = IdentifyAndPlan(contexts.params, named_composition(CHR2, 8), extensions=CHR2)
    assert aware.observation.light_mW_per_mm2 == 5.0
    unaware = IdentifyAndPlan(contexts.params, named_composition(None, 8))
    assert unaware.observation.light_mW_per_mm2 is None
    lit = evaluate_policy(contexts, aware, extensions=CHR2, seed=0).returns
    pulsed = evaluate_policy(contexts, unaware, extensions=CHR2, seed=0).returns
    assert lit.mean() > pulsed.mean() + 0.15


def test_the_light_is_read_by_the_papers_tracker_alone():
    """A composition whose tracker is another (potentials filtered under noise, each
    neuron's threshold and leak learned) is refused under the light when it is built, in
    one line; the paper's tracker takes the light with noise or heterogeneity."""
    from spikectl.planning import Composition, IdentifyAndPlan
    from spikectl.planning.observing import ObservationSettings

    noisy = Extensions(actuator="chr2", observation_noise_mV=1.0)
    uneven = Extensions(actuator="chr2", threshold_spread=0.1)
    filtering = ObservationSettings(task_model=True, filter_voltage=True)
    learning = ObservationSettings(task_model=True)  # each neuron's threshold and leak
    for settings, extensions in ((filtering, noisy), (learning, uneven)):
        with pytest.raises(ValueError, match="ChR2 actuator is read by the paper's tracker alone"):
            settings.bind(PARAMS, extensions)
        with pytest.raises(ValueError, match="ChR2 actuator is read by the paper's tracker alone"):
            IdentifyAndPlan(PARAMS, Composition("x", observation=settings), extensions=extensions)
    for extensions in (noisy, uneven):
        reader = ObservationSettings().bind(PARAMS, extensions).reader(8)
        assert reader.opsin is not None
