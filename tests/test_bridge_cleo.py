"""spikectl.bridges.cleo: spikectl's controllers on a Brian 2 network in Cleo's closed loop.

Needs the cleo extra in its own virtualenv (CI: .ci/run's Cleo block;
``pip install -c constraints-cleo.txt -e ".[cleo,dev]"``); without it only the
missing-extra error is tested and the rest skips, saying so.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from spikectl.config_errors import ConfigError
from spikectl.contexts import Context, ContextSet
from spikectl.envs.controller import RandomLegal, Witness, play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING

INSTALL = 'pip install -c constraints-cleo.txt -e ".[cleo,dev]"'


def test_missing_extra_is_one_named_line():
    """Without Cleo (hidden from the import system here), importing the bridge raises
    MissingExtraError in one line that gives the install command."""
    code = (
        "import sys\n"
        "sys.modules['cleo'] = None\n"
        "sys.modules['brian2'] = None\n"
        "import spikectl.bridges\n"
        "try:\n"
        "    import spikectl.bridges.cleo\n"
        "except Exception as error:\n"
        "    print(type(error).__name__)\n"
        "    print(error)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, timeout=120)  # fmt: skip
    name, message = result.stdout.splitlines()
    assert name == "MissingExtraError"
    assert 'pip install -c constraints-cleo.txt "spikectl[cleo]"' in message


cleo_bridge = pytest.importorskip(
    "spikectl.bridges.cleo",
    reason=f"the cleo extra (cleosim, Brian 2) is not installed: {INSTALL}",
    exc_type=ImportError,
)


@pytest.fixture(scope="module")
def test_set() -> ContextSet:
    from spikectl.experiments.suite import load_split

    return load_split("paper", "test")


class Scripted:
    """Plays a fixed action sequence and keeps every observation it was shown."""

    def __init__(self, actions):
        self.actions = list(actions)
        self.seen = []

    def reset(self):
        self.seen = []

    def act(self, observation, info):
        self.seen.append((observation, info))
        return self.actions[observation["step"]]


def two_neuron_set(weight: int, length: int = 6) -> ContextSet:
    weights = np.array([[0, weight, 0], [0, 0, 0], [0, 0, 0]], dtype=np.int8)
    pattern = np.zeros(length, dtype=bool)
    pattern[1] = True
    return ContextSet([Context(weights, 1, pattern)], NeuronParams())


def test_a_pulse_and_a_release_hand_computed():
    """Neuron 0 stimulated at rest reads -70 + 40 = -30 mV (a spike) and releases onto
    neuron 1, which the next step reads -70 + 20 = -50 mV (the threshold: a spike), and
    is back at rest (refractory) the step after, as in docs/model.md."""
    contexts = two_neuron_set(+1)
    loop = cleo_bridge.CleoLoop(contexts)
    controller = Scripted([0, -1, -1, -1, -1, -1])
    episode = loop.play(controller, 0)
    _, total = play_episode(NeuronControlEnv(contexts=contexts), controller, 0)
    voltages = np.array([seen[0]["voltage"] for seen in controller.seen])
    np.testing.assert_allclose(voltages[1], [-30.0, -70.0, -70.0], atol=1e-9)
    np.testing.assert_allclose(voltages[2], [-70.0, -50.0, -70.0], atol=1e-9)
    np.testing.assert_allclose(voltages[3], [-70.0, -70.0, -70.0], atol=1e-9)
    assert controller.seen[1][1]["spikes"].tolist() == [True, False, False]
    assert controller.seen[2][1]["target_spiked"] is True
    assert episode.target_spikes.tolist() == [False, True, False, False, False, False]
    assert episode.total == total > 0.99  # the pattern met: 1 up to the sum's rounding


def test_depression_blocks_a_release_within_the_interval():
    """A neuron stimulated at steps 0 and 2 spikes twice but releases only once (the
    release interval is 5 steps): neuron 1 is driven once."""
    loop = cleo_bridge.CleoLoop(two_neuron_set(+1))
    controller = Scripted([0, -1, 0, -1, -1, -1])
    episode = loop.play(controller, 0)
    assert episode.target_spikes.tolist() == [False, True, False, False, False, False]
    np.testing.assert_allclose(controller.seen[4][0]["voltage"][1], -70.0, atol=1e-9)


def test_ideal_setting_equals_the_environment(test_set):
    """Ideal sensing and pulse, no latency: every action, every target spike and the
    return equal NeuronControlEnv's, for the planners and the privileged references."""
    from spikectl.training.loaders import load_controller

    env = NeuronControlEnv(contexts=test_set)
    loop = cleo_bridge.CleoLoop(test_set)
    for name in ("identify-and-plan", "oracle", "random"):
        for context in (0, 1, 2):
            controller = load_controller(name, env=env, seed=context)
            actions, total = play_episode(env, controller, context)
            spikes = env.unwrapped._spike_history[:, test_set[context].target].copy()
            controller = load_controller(name, env=env, seed=context)
            episode = loop.play(controller, context)
            np.testing.assert_array_equal(episode.actions, actions, err_msg=f"{name} {context}")
            np.testing.assert_array_equal(episode.target_spikes, spikes)
            assert episode.total == total


@pytest.mark.parametrize("latency", [1, 3])
def test_latency_delays_every_action(test_set, latency):
    """With latency L an open-loop controller (the witness) acts as the environment
    does on its actions shifted by L steps, the first L doing nothing."""
    setting = cleo_bridge.CleoSetting(latency_ms=latency)
    loop = cleo_bridge.CleoLoop(test_set, setting)
    env = NeuronControlEnv(contexts=test_set)
    for context in (0, 1):
        episode = loop.play(Witness(test_set), context)
        shifted = np.concatenate([np.full(latency, DO_NOTHING), episode.actions[:-latency]])
        _, total = play_episode(env, Scripted(shifted), context)
        assert episode.total == total
        assert total < 1.0  # the witness's timing matters


class Recording:
    """A controller that plays another and keeps every observation it was shown."""

    def __init__(self, controller):
        self.controller, self.seen = controller, []

    def reset(self):
        self.seen = []
        self.controller.reset()

    def act(self, observation, info):
        self.seen.append(observation)
        return self.controller.act(observation, info)


@pytest.mark.parametrize("latency", [1, 2])
def test_latency_settings_equal_the_environment_with_latency_steps(test_set, latency):
    """Cleo's latency{L} and spikectl's extensions={"latency_steps": L}: the same
    observations (actions in flight included), actions, target spikes and returns, for the
    latency-aware oracle, a random controller and identify-and-plan (5 episodes each L)."""
    env = NeuronControlEnv(contexts=test_set, extensions={"latency_steps": latency})
    loop = cleo_bridge.CleoLoop(test_set, cleo_bridge.SETTINGS[f"latency{latency}"])
    for name, contexts in (("oracle", (0, 1)), ("random", (0, 1)), ("identify-and-plan", (2,))):
        for context in contexts:
            played_alike(env, loop, test_set, name, context)


def played_alike(env, loop, test_set, name: str, context: int) -> list[dict]:
    """Play the registered controller ``name`` on ``context`` in spikectl's environment
    and in Cleo's loop, assert the same actions, target spikes, return and observations,
    and return the observations Cleo's copy saw."""
    from spikectl.training.loaders import load_controller

    ours = Recording(load_controller(name, env=env, seed=context))
    actions, total = play_episode(env, ours, context)
    spikes = env.unwrapped._spike_history[:, test_set[context].target].copy()
    theirs = Recording(load_controller(name, env=env, seed=context))
    episode = loop.play(theirs, context)
    np.testing.assert_array_equal(episode.actions, actions, err_msg=f"{name} {context}")
    np.testing.assert_array_equal(episode.target_spikes, spikes)
    assert episode.total == total
    for a, b in zip(ours.seen, theirs.seen, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name} {key}")
    return theirs.seen


def test_every_setting_has_its_matching_extensions():
    """The spikectl loop each Cleo setting models: latency in steps, the actuator at the
    same irradiance, the sensing and the noise's sigma; the ideal one is the paper's."""
    assert cleo_bridge.matching_extensions(cleo_bridge.IDEAL) == Extensions()
    for name, setting in cleo_bridge.SETTINGS.items():
        extensions = cleo_bridge.matching_extensions(setting)
        assert extensions.latency_steps == setting.latency_ms, name
        assert (extensions.actuator, extensions.sensing) == (setting.actuation, setting.sensing)
        assert extensions.observation_noise_mV == setting.noise_mV
    assert cleo_bridge.matching_extensions(cleo_bridge.SETTINGS["chr2-latency2-spikes"]) == (
        Extensions(actuator="chr2", latency_steps=2, sensing="spikes")
    )


def test_the_rigs_loop_without_background_equals_the_environment(test_set):
    """ChR2, 2 ms of latency and spikes-only sensing at once (suite v2's rig without its
    background input): the oracle made for that loop and a random controller play as
    they do in spikectl's environment with the matching extensions."""
    setting = cleo_bridge.SETTINGS["chr2-latency2-spikes"]
    env = NeuronControlEnv(contexts=test_set, extensions=cleo_bridge.matching_extensions(setting))
    loop = cleo_bridge.CleoLoop(test_set, setting)
    for name, context in (("oracle", 0), ("random", 1)):
        for seen in played_alike(env, loop, test_set, name, context):
            assert "voltage" not in seen and len(seen["actions_in_flight"]) == 2


def test_spikes_only_equals_the_environment_with_spikes_only_sensing(test_set):
    """Cleo's spikes-only setting (its ground-truth spike recorder) and spikectl's
    extensions={"sensing": "spikes"}: the same observations (spikes, no voltage), actions,
    target spikes and returns for the oracle and a random controller, over consecutive
    episodes of one loop (the recorder's count restarts at each reset)."""
    env = NeuronControlEnv(contexts=test_set, extensions={"sensing": "spikes"})
    loop = cleo_bridge.CleoLoop(test_set, cleo_bridge.SETTINGS["spikes-only"])
    spiked = 0
    for name, context in (("random", 0), ("oracle", 1), ("random", 2)):
        for seen in played_alike(env, loop, test_set, name, context):
            assert "voltage" not in seen
            spiked += int(seen["spikes"].sum())
    assert spiked > 0  # spikes were compared, not only zeros


def test_noise_is_seeded_and_only_in_what_is_measured(test_set):
    """Noise of 1 mV moves the observed potentials (sd ~1 mV around the true ones),
    is the same for the same seed, and changes no dynamics: an open-loop controller
    scores as without noise."""
    setting = cleo_bridge.CleoSetting(noise_mV=1.0, noise_seed=3)
    quiet, noisy = Scripted([DO_NOTHING] * 60), Scripted([DO_NOTHING] * 60)
    cleo_bridge.CleoLoop(test_set).play(quiet, 0)
    loop = cleo_bridge.CleoLoop(test_set, setting)
    episode = loop.play(noisy, 0)
    differences = np.array([n[0]["voltage"] - q[0]["voltage"]
                            for n, q in zip(noisy.seen, quiet.seen, strict=True)])  # fmt: skip
    assert 0.9 < differences.std() < 1.1
    again = Scripted([DO_NOTHING] * 60)
    loop.play(again, 0)
    np.testing.assert_array_equal(again.seen[5][0]["voltage"], noisy.seen[5][0]["voltage"])
    _, total = play_episode(NeuronControlEnv(contexts=test_set), Scripted([DO_NOTHING] * 60), 0)
    assert episode.total == total


def test_chr2_light_drives_only_its_neuron():
    """With ChR2, one 1 ms light pulse on neuron 0 at rest makes it spike within a few
    steps, and neuron 2 (no synapse from 0, its own dark fibre) stays exactly at rest."""
    loop = cleo_bridge.CleoLoop(two_neuron_set(0), cleo_bridge.CleoSetting(actuation="chr2"))
    controller = Scripted([0, -1, -1, -1, -1, -1])
    loop.play(controller, 0)
    voltages = np.array([seen[0]["voltage"] for seen in controller.seen])
    spikes = np.array([seen[1]["spikes"] for seen in controller.seen[1:]])
    assert spikes[:, 0].any()
    assert not spikes[:, 1:].any()
    assert np.all(voltages[:, 1:] == np.float32(-70.0))


class Probing(Scripted):
    """A scripted controller that also reads ``probe()`` whenever it is asked to act."""

    def __init__(self, actions, probe):
        super().__init__(actions)
        self.probe, self.probed = probe, []

    def act(self, observation, info):
        self.probed.append(self.probe())
        return super().act(observation, info)


class Watching:
    """A controller that keeps the potentials it was shown and lets ``inner`` act."""

    def __init__(self, inner):
        self.inner, self.seen = inner, []

    def reset(self):
        self.inner.reset()
        self.seen = []

    def act(self, observation, info):
        self.seen.append(observation["voltage"])
        return self.inner.act(observation, info)


def test_chr2_photocurrent_equals_spikectls_opsin():
    """One 1 ms light pulse on a resting neuron: the current Cleo's ChR2 gives it at every
    step (read from Brian's summed Iopto, which the controller sees one step after the
    step that integrated it) equals spikectl's opsin drive, spikes and reset included."""
    length = 14
    contexts = two_neuron_set(0, length)
    actions = [DO_NOTHING, DO_NOTHING, 0] + [DO_NOTHING] * (length - 3)
    loop = cleo_bridge.CleoLoop(contexts, cleo_bridge.CleoSetting(actuation="chr2"))
    probing = Probing(actions, lambda: np.asarray(loop.neurons.Iopto_) / 1e-12)
    loop.play(probing, 0)
    cleo_pA = np.array(probing.probed[1:])  # [step, neuron]: the current of steps 0..N-2
    env = NeuronControlEnv(contexts=contexts, extensions=Extensions(actuator="chr2"))
    env.reset(options={"context": 0})
    spikectl_pA, spikes = [], []
    for action in actions[:-1]:
        spikes.append(env.step(action)[4]["spikes"][0])
        spikectl_pA.append(env.unwrapped._drawn.input_mV[0, 0] * env.params.capacitance_pF)
    np.testing.assert_allclose(np.array(spikectl_pA), cleo_pA, rtol=1e-9, atol=1e-9)
    assert cleo_pA[3, 0] == pytest.approx(696.98497, rel=1e-7)  # the step after the pulse
    assert np.flatnonzero(spikes).tolist() == [3, 6, 10]
    assert not cleo_pA[:, 1:].any()


def test_chr2_agrees_with_the_environment_on_test_networks(test_set):
    """The same light pulses (a seeded random controller) in Cleo's chr2 setting and in
    spikectl's opsin environment: the spike rasters of every neuron agree in >= 99 % of
    neuron-steps (measured: all of them, docs/extensions.md), the observed potentials
    to float32 rounding."""
    loop = cleo_bridge.CleoLoop(test_set, cleo_bridge.CleoSetting(actuation="chr2"))
    env = NeuronControlEnv(contexts=test_set, extensions=Extensions(actuator="chr2"))
    length, n = test_set.episode_length, test_set.n_neurons
    agreeing = 0
    for context in (0, 1, 2):
        watched = Watching(RandomLegal(context))
        episode = loop.play(watched, context)
        cleo_raster = np.zeros((length, n), dtype=bool)
        steps = np.rint(np.asarray(loop._spikes.t / loop._step)).astype(np.int64)
        cleo_raster[steps, np.asarray(loop._spikes.i)] = True
        observation, _ = env.reset(options={"context": context})
        raster, voltages = np.zeros((length, n), dtype=bool), [observation["voltage"]]
        for step, action in enumerate(episode.actions.tolist()):
            observation, _, _, _, info = env.step(action)
            raster[step], _ = info["spikes"], voltages.append(observation["voltage"])
        agreeing += int((raster == cleo_raster).sum())
        np.testing.assert_allclose(voltages[:length], watched.seen, atol=1e-4)
        assert cleo_raster.sum() > 10  # the light drives the network
    assert agreeing / (3 * length * n) >= 0.99


@pytest.mark.parametrize(
    "fields, problem",
    [
        ({"actuation": "laser"}, "actuation"),
        ({"latency_ms": -1}, "latency_ms"),
        ({"latency_ms": 1.5}, "latency_ms"),
        ({"noise_mV": float("nan")}, "noise_mV"),
        ({"opsin_dt_ms": 0.3}, "opsin_dt_ms"),
        ({"sensing": "volts"}, "sensing"),
        ({"sensing": "spikes", "noise_mV": 1.0}, "noise_mV must be 0 with sensing"),
    ],
)
def test_bad_settings_are_named(fields, problem):
    with pytest.raises(ConfigError, match=problem):
        cleo_bridge.CleoSetting(**fields)


def test_bad_contexts_and_illegal_actions_are_refused():
    loop = cleo_bridge.CleoLoop(two_neuron_set(1))
    with pytest.raises(IndexError, match="out of range"):
        loop.play(Scripted([DO_NOTHING] * 6), 1)
    with pytest.raises(ValueError, match="not legal"):
        loop.play(Scripted([1] * 6), 0)  # the target


def test_the_example_prints_equal_returns_in_the_ideal_setting(capsys):
    """examples/cleo_closed_loop.py on one test network: spikectl's return and the ideal
    setting's are the same number."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "examples" / "cleo_closed_loop.py"
    spec = importlib.util.spec_from_file_location("cleo_closed_loop", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    assert example.main(["--networks", "1", "--settings", "ideal"]) == 0
    last = capsys.readouterr().out.splitlines()[-1].split()
    assert last[0] == "0" and last[1] == last[2]
    assert example.main(["--settings", "nonsense"]) == 2
