"""The ChR2 actuator (spikectl.neuron.opsin, ``Extensions(actuator="chr2")``): the kinetics
on hand-checkable cases, the pulse's effect on a neuron, the environments with it, bad
inputs. Agreement with Cleo's ChR2 is in tests/test_bridge_cleo.py (Cleo's virtualenv)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from spikectl.config_errors import ConfigError
from spikectl.contexts import Context, ContextSet
from spikectl.envs.controller import RandomLegal
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.registration import flat_id
from spikectl.envs.rollout import evaluate_policy
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron import opsin
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.opsin import OpsinActuator
from spikectl.neuron.params import NeuronParams

PARAMS = NeuronParams()
CHR2 = Extensions(actuator="chr2")
SHORT = {"contexts": {"n_train": 6, "n_test": 2}, "episode_length": 12}


def actuator(batch=1, n=3, irradiance=5.0):
    return OpsinActuator(batch, n, irradiance, PARAMS.dt_ms, PARAMS.capacitance_pF)


def run(opsins, lit_per_step, voltage_mV=-70.0):
    """Drive [steps, B, n] in mV, one step per row of ``lit_per_step`` ([steps, B])."""
    batch, n = opsins.c1.shape
    voltage = np.full((batch, n), voltage_mV)
    drives = []
    for lit in lit_per_step:
        out = np.full((batch, 1, n), np.nan)
        opsins.illuminate(voltage, np.asarray(lit, dtype=np.int64).reshape(batch, 1), out)
        drives.append(out[:, 0].copy())
    return np.array(drives)


def steady_state(flux: float) -> np.ndarray:
    """[C1, O1, O2, C2] where the rate equations' derivatives vanish, with the occupancies
    summing to 1: the null space of the generator, solved directly (no integration)."""
    ga1, ga2, gf, gb = opsin.light_rates(flux)
    gd1, gd2, gr0 = opsin.GD1_PER_ms, opsin.GD2_PER_ms, opsin.GR0_PER_ms
    generator = np.array([  # d[C1, O1, O2, C2]/dt = generator @ [C1, O1, O2, C2]
        [-ga1, gd1, 0.0, gr0],
        [ga1, -(gd1 + gf), gb, 0.0],
        [0.0, gf, -(gd2 + gb), ga2],
        [0.0, 0.0, gd2, -(ga2 + gr0)],
    ])  # fmt: skip
    system = np.vstack([generator[:3], np.ones(4)])
    return np.linalg.solve(system, [0.0, 0.0, 0.0, 1.0])


def test_no_light_no_current_and_the_opsin_stays_at_rest():
    opsins = actuator(batch=2)
    drives = run(opsins, [[-1, -1]] * 50)
    assert (drives == 0).all()
    assert (opsins.c1 == 1).all() and (opsins.o1 == 0).all() and (opsins.o2 == 0).all()


def test_the_fibre_and_the_flux_by_hand():
    # Foutz et al. at 50 um on the axis: 1/sqrt(2 pi) * (R0 / (R0 + z tan(asin(NA / n))))^2 * M
    spread = np.tan(np.arcsin(0.37 / 1.36))
    a = 1 + 0.125 / 7.37
    b = np.sqrt(a * a - 1)
    m = b / (a * np.sinh(b * 7.37 * 0.05) + b * np.cosh(b * 7.37 * 0.05))
    expected = (0.1 / (0.1 + 0.05 * spread)) ** 2 * m / np.sqrt(2 * np.pi)
    assert opsin.fibre_transmittance() == pytest.approx(expected, rel=1e-12)
    assert opsin.fibre_transmittance() == pytest.approx(0.2223387, rel=1e-6)  # Cleo's value
    photon_energy = 6.63e-34 * 2.998e8 / 473e-9
    assert opsin.photon_flux(5.0) == pytest.approx(5e-3 * expected / photon_energy, rel=1e-12)
    np.testing.assert_array_equal(opsin.light_rates(0.0), [0, 0, 0.0373, 0.0161])


def test_constant_light_reaches_the_steady_state_of_the_rate_equations():
    irradiance = 50.0
    opsins = actuator(batch=1, n=2, irradiance=irradiance)
    run(opsins, [[0]] * 4000)  # 4 s of light on neuron 0; the slowest mode decays in ~0.2 s
    expected = steady_state(opsin.photon_flux(irradiance))
    state = [opsins.c1[0, 0], opsins.o1[0, 0], opsins.o2[0, 0], opsins.c2[0, 0]]
    np.testing.assert_allclose(state, expected, rtol=1e-9, atol=1e-12)
    assert expected[1] > 0.01  # light opens a real fraction of the channels
    # The current is g0 (O1 + gamma O2) v1 (exp(70 / v0) - 1) at -70 mV, in mV per step.
    current = 114.0 * (expected[1] + 0.00742 * expected[2]) * 17.1 * (np.exp(70 / 43) - 1)
    drive = run(opsins, [[0]])[0, 0, 0]
    assert drive == pytest.approx(current / 30.0, rel=1e-9)
    assert opsins.c1[0, 1] == 1  # the dark neuron never moved


@pytest.mark.parametrize("irradiance", [0.0, 5.0, 1000.0])
def test_a_step_is_ten_euler_substeps_of_the_rate_equations(irradiance):
    """The composed map of a step equals ten explicit Euler sub-steps of 0.1 ms, whose
    derivatives are the rate equations written out here."""
    rates = opsin.light_rates(opsin.photon_flux(irradiance))
    ga1, ga2, gf, gb = rates
    rng = np.random.default_rng(4)
    for _ in range(20):
        state = rng.dirichlet(np.ones(4))  # C1, O1, O2, C2
        c1, o1, o2, c2 = state
        for _ in range(10):
            c1, o1, o2, c2 = (
                c1 + 0.1 * (0.105 * o1 + 0.00033 * c2 - ga1 * c1),
                o1 + 0.1 * (ga1 * c1 + gb * o2 - (0.105 + gf) * o1),
                o2 + 0.1 * (ga2 * c2 + gf * o1 - (0.0138 + gb) * o2),
                c2 + 0.1 * (ga2 * -c2 + 0.0138 * o2 - 0.00033 * c2),
            )
        step_map = opsin.euler_step_map(rates, 0.1, 10)
        mapped = step_map[:, :3] @ state[:3] + step_map[:, 3]
        np.testing.assert_allclose(mapped, [c1, o1, o2], rtol=1e-12, atol=1e-15)
        assert sum([c1, o1, o2, c2]) == pytest.approx(1.0, abs=1e-12)


def test_occupancies_stay_in_the_unit_interval_and_sum_to_one():
    rng = np.random.default_rng(3)
    opsins = actuator(batch=5, n=4, irradiance=1000.0)  # saturating light, the hardest case
    for _ in range(300):
        run(opsins, [rng.integers(-1, 4, size=5)])
        states = np.stack([opsins.c1, opsins.o1, opsins.o2, opsins.c2])
        assert (states >= 0).all() and (states <= 1).all()
        np.testing.assert_allclose(states.sum(axis=0), 1.0, rtol=0, atol=1e-12)


def test_one_pulse_makes_a_resting_neuron_spike_at_the_next_step_and_three_later():
    # Cleo's trace of this pulse (tests/test_bridge_cleo.py checks it against Cleo itself):
    # the current of each step, at rest, in pA.
    opsins = actuator(batch=1, n=3)
    drives = run(opsins, [[-1], [-1], [0]] + [[-1]] * 4)[:, 0, 0] * PARAMS.capacitance_pF
    np.testing.assert_allclose(drives, [0, 0, 0, 696.98497, 604.46166, 524.61733, 455.70440],
                               rtol=1e-7)  # fmt: skip
    length = 12
    weights = np.zeros((3, 3), dtype=np.int8)
    pattern = np.zeros(length, dtype=bool)
    pattern[1] = True
    contexts = ContextSet([Context(weights, 1, pattern)], PARAMS)
    env = NeuronControlEnv(contexts=contexts, extensions=CHR2)
    env.reset(options={"context": 0})
    spiked, voltages = [], []
    for step in range(length):
        observation, _, _, _, info = env.step(0 if step == 2 else -1)
        spiked.append(bool(info["spikes"][0]))
        voltages.append(float(observation["voltage"][0]))
    assert np.flatnonzero(spiked).tolist() == [3, 6, 10]  # as Cleo's (docs/cleo.md)
    assert voltages[3] == pytest.approx(-70 + 696.98497 / 30, abs=1e-4)
    assert not any(info["spikes"][1:])
    # The same network with the paper's pulse spikes at the step of the action only.
    paper = NeuronControlEnv(contexts=contexts)
    paper.reset(options={"context": 0})
    assert [bool(paper.step(0 if s == 2 else -1)[4]["spikes"][0]) for s in range(6)] == [
        False, False, True, False, False, False]  # fmt: skip


def test_a_refractory_neuron_ignores_the_current_but_its_opsin_still_sees_light():
    weights = np.zeros((3, 3), dtype=np.int8)
    pattern = np.zeros(8, dtype=bool)
    pattern[1] = True
    contexts = ContextSet([Context(weights, 1, pattern)], PARAMS)
    lit_twice = NeuronControlEnv(contexts=contexts, extensions=CHR2)
    lit_twice.reset(options={"context": 0})
    # Lit at 0 and 1: it spikes at 1, is held at 2 (refractory), then fires on the
    # channels that both pulses opened.
    spikes = [lit_twice.step(0 if s < 2 else -1)[4]["spikes"][0] for s in range(8)]
    assert spikes[1] and not spikes[2]
    assert lit_twice._opsin.o1[0, 0] > 0


@pytest.mark.parametrize(
    "extensions",
    [CHR2, Extensions(actuator="chr2", light_irradiance_mW_per_mm2=20.0,
                      stochastic_release=True, background_rate=0.05)],
    ids=["chr2", "chr2+stochastic+background"],
)  # fmt: skip
def test_single_and_vector_envs_give_identical_episodes(extensions):
    num_envs = 3
    kwargs = {**SHORT, "extensions": extensions}
    batched = NeuronControlVectorEnv(num_envs=num_envs, **kwargs)
    sync = SyncVectorEnv([lambda: NeuronControlEnv(**kwargs) for _ in range(num_envs)],
                         autoreset_mode=AutoresetMode.NEXT_STEP)  # fmt: skip
    obs_a, info_a = batched.reset(seed=5)
    obs_b, _ = sync.reset(seed=5)
    rng = np.random.default_rng(8)
    spikes = 0
    for step in range(3 * 13 + 2):  # three episodes with their autoresets
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key], err_msg=f"{step} {key}")
        actions = np.array([rng.choice(np.flatnonzero(m)) - 1 for m in info_a["action_mask"]])
        obs_a, rewards_a, _, _, info_a = batched.step(actions)
        obs_b, rewards_b, _, _, info_b = sync.step(actions)
        np.testing.assert_array_equal(rewards_a, rewards_b)
        present = info_b.get("_spikes", np.zeros(num_envs, dtype=bool))
        np.testing.assert_array_equal(info_a["_spikes"], present)
        if present.any():
            np.testing.assert_array_equal(info_a["spikes"][present], info_b["spikes"][present])
            spikes += int(info_a["spikes"][present].sum())
    assert spikes > 10  # the light drives the networks


def test_the_opsin_changes_the_episodes_and_a_seed_repeats_them():
    test_set = NeuronControlEnv(**SHORT).contexts
    paper = evaluate_policy(test_set, RandomLegal(seed=1))
    first = evaluate_policy(test_set, RandomLegal(seed=1), extensions=CHR2)
    again = evaluate_policy(test_set, RandomLegal(seed=1), extensions=CHR2)
    np.testing.assert_array_equal(paper.actions, first.actions)
    assert not np.array_equal(paper.spikes, first.spikes)
    np.testing.assert_array_equal(first.spikes, again.spikes)
    unlit = Extensions(actuator="chr2", light_irradiance_mW_per_mm2=0)
    dark = evaluate_policy(test_set, RandomLegal(seed=1), extensions=unlit)
    assert not dark.spikes.any()  # no light, no pulse: nothing ever spikes


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"actuator": "laser"}, r"^Extensions.actuator must be one of \('pulse', 'chr2'\), "
                                r"got 'laser'$"),
        ({"actuator": None}, "^Extensions.actuator must be one of"),
        ({"actuator": "chr2", "light_irradiance_mW_per_mm2": -1.0},
         r"^Extensions.light_irradiance_mW_per_mm2 must lie in \[0, 1e\+06\] mW/mm\^2, got -1$"),
        ({"light_irradiance_mW_per_mm2": float("nan")}, "must be finite"),
        ({"light_irradiance_mW_per_mm2": 1e7}, "must lie in"),
    ],
)  # fmt: skip
def test_bad_settings_are_one_config_error_line(kwargs, message):
    with pytest.raises(ConfigError, match=message) as error:
        Extensions(**kwargs)
    assert "\n" not in str(error.value)


def test_the_registered_variant_and_its_flat_twin():
    env = gym.make("spikectl/NeuronControlChR2-v0", **SHORT)
    assert env.unwrapped.extensions.actuator == "chr2"
    assert env.unwrapped.extensions.light_irradiance_mW_per_mm2 == 5.0
    flat = gym.make(flat_id("spikectl/NeuronControlChR2-v0"), **SHORT)
    flat.reset(seed=0)
    assert flat.unwrapped.env.unwrapped.extensions.actuator == "chr2"
    vector = gym.make_vec("spikectl/NeuronControlChR2-v0", num_envs=2, **SHORT)
    assert vector.extensions == Extensions(actuator="chr2")
    assert Extensions.from_dict(CHR2.to_dict(only_changed=True)) == CHR2
    assert Extensions().to_dict(only_changed=True) == {}


def test_an_opsin_environment_pickles_mid_episode_and_continues_identically():
    import pickle

    env = NeuronControlEnv(**SHORT, extensions=CHR2)
    _, info = env.reset(seed=2)
    rng = np.random.default_rng(6)
    actions = rng.choice(np.flatnonzero(info["action_mask"]) - 1, size=12)
    for action in actions[:4]:
        env.step(int(action))
    twin = pickle.loads(pickle.dumps(env))
    for action in actions[4:]:
        first, second = env.step(int(action)), twin.step(int(action))
        np.testing.assert_array_equal(first[0]["voltage"], second[0]["voltage"])
        assert first[1] == second[1]
    assert twin._opsin is not env._opsin and twin._opsin.o1.any()
