"""Text and image rasters of episodes, from arrays and from the environments."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.contexts import ContextSet, make_context
from spikectl.envs import render
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.vector_env import NeuronControlVectorEnv

# Three neurons, edge 0 -> 2, target 2, pattern: spike at step 1 only.
PATTERN = np.array([0, 1, 0, 0, 0, 0], dtype=np.int8)
HIT_ACTIONS = [0, -1, 1, 0]  # n0 makes the target hit step 1; n1 and n0 again later
MISS_ACTIONS = [-1, 0, -1]  # too late: a miss at step 1, an unwanted spike at step 2


def tiny_contexts() -> ContextSet:
    weights = np.zeros((3, 3), dtype=np.int8)
    weights[0, 2] = 1
    witness = [0, -1, -1, -1, -1, -1]
    return ContextSet([make_context(weights, target=2, pattern=PATTERN, witness=witness)])


def played(actions, render_mode="ansi"):
    env = NeuronControlEnv(contexts=tiny_contexts(), render_mode=render_mode)
    env.reset(seed=0)
    for action in actions:
        env.step(action)
    return env


def episode_arrays(actions):
    env = played(actions)
    spikes = env._spike_history
    return PATTERN, spikes[:, 2], env._action_history[0], spikes, 2, len(actions)


EXPECTED_HIT_EPISODE = """\
step 4/6  target n2  hits 1/1  correct silences 3/3
            0
            012345
pattern     .|....
n2 target   .|..
stimulus    0.10
n0          *..*
n1          ..*.
legend: target | hit, o missed spike, x unwanted spike; neurons | spike, * stimulated
"""


def test_ansi_raster_of_a_known_episode():
    assert render.render_ansi(*episode_arrays(HIT_ACTIONS)) == EXPECTED_HIT_EPISODE
    assert played(HIT_ACTIONS).render() == EXPECTED_HIT_EPISODE


def test_ansi_marks_misses_and_unwanted_spikes():
    lines = render.render_ansi(*episode_arrays(MISS_ACTIONS)).splitlines()
    assert lines[0] == "step 3/6  target n2  hits 0/1  correct silences 1/2"
    assert lines[4] == "n2 target   .ox"
    assert lines[6] == "n0          .*."


def test_ansi_after_reset_and_for_large_networks():
    lines = played([]).render().splitlines()
    assert lines[3] == "pattern     .|...."
    assert lines[4] == "n2 target"
    spikes = np.zeros((1, 40), dtype=bool)
    text = render.render_ansi([1, 0], spikes[:, 0], [39], spikes, 0, 1)
    assert "stimulus    *" in text.splitlines()


def cell_colour(image: np.ndarray, row: int, step: int) -> tuple[int, ...]:
    cell = image[render.cell_box(row, step)]
    colours = np.unique(cell.reshape(-1, 3), axis=0)
    assert len(colours) == 1, "a cell has one colour"
    return tuple(int(c) for c in colours[0])


def test_rgb_raster_colours():
    image = render.render_rgb(*episode_arrays(HIT_ACTIONS))
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    assert image.shape[0] % 16 == 0 and image.shape[1] % 16 == 0
    # Every cell lies inside the image: rows pattern, target, stimulus, n0, n1.
    assert render.cell_box(render.FIRST_NEURON_ROW + 1, 5)[0].stop <= image.shape[0]
    assert cell_colour(image, render.ROW_PATTERN, 1) == render.PATTERN_SPIKE
    assert cell_colour(image, render.ROW_PATTERN, 0) == render.SILENT
    assert cell_colour(image, render.ROW_PATTERN, 5) == render.SILENT  # the pattern is known
    assert cell_colour(image, render.ROW_TARGET, 1) == render.HIT
    assert cell_colour(image, render.ROW_TARGET, 0) == render.SILENT
    assert cell_colour(image, render.ROW_TARGET, 4) == render.FUTURE
    assert cell_colour(image, render.ROW_STIMULUS, 0) == render.STIMULUS
    assert cell_colour(image, render.ROW_STIMULUS, 1) == render.SILENT
    assert cell_colour(image, render.FIRST_NEURON_ROW, 0) == render.STIMULUS  # n0
    assert cell_colour(image, render.FIRST_NEURON_ROW, 1) == render.SILENT
    assert cell_colour(image, render.FIRST_NEURON_ROW + 1, 2) == render.STIMULUS  # n1

    image = render.render_rgb(*episode_arrays(MISS_ACTIONS))
    assert cell_colour(image, render.ROW_TARGET, 1) == render.MISS
    assert cell_colour(image, render.ROW_TARGET, 2) == render.EXTRA


def test_spikes_and_refractory_stimulation_in_the_image():
    # n0 spikes at step 0 and is stimulated while refractory at step 1.
    spikes = np.zeros((2, 3), dtype=bool)
    spikes[0, 0] = True
    image = render.render_rgb(PATTERN, spikes[:, 2], [-1, 0], spikes, 2, 2)
    assert cell_colour(image, render.FIRST_NEURON_ROW, 0) == render.SPIKE
    assert cell_colour(image, render.FIRST_NEURON_ROW, 1) == render.STIMULATED_SILENT


def test_env_rgb_array_render():
    env = played(HIT_ACTIONS, render_mode="rgb_array")
    np.testing.assert_array_equal(env.render(), render.render_rgb(*episode_arrays(HIT_ACTIONS)))


def test_vector_env_renders_every_sub_env():
    for mode in ("ansi", "rgb_array"):
        envs = NeuronControlVectorEnv(num_envs=2, contexts=tiny_contexts(), render_mode=mode)
        envs.reset(seed=0)
        for action in HIT_ACTIONS:
            envs.step(np.array([action, -1]))
        frames = envs.render()
        assert isinstance(frames, tuple) and len(frames) == 2
        expected = played(HIT_ACTIONS, render_mode=mode).render()
        if mode == "ansi":
            assert frames[0] == expected
        else:
            np.testing.assert_array_equal(frames[0], expected)


def test_render_without_a_mode_warns():
    env = played([], render_mode=None)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    envs = NeuronControlVectorEnv(num_envs=2, contexts=tiny_contexts())
    envs.reset()
    with pytest.warns(UserWarning, match="render_mode"):
        assert envs.render() is None


def test_bad_render_inputs():
    spikes = np.zeros((6, 3), dtype=bool)
    with pytest.raises(ValueError, match="step 7"):
        render.render_ansi(PATTERN, spikes[:, 2], np.full(6, -1), spikes, 2, 7)
    with pytest.raises(ValueError, match="target 3"):
        render.render_rgb(PATTERN, spikes[:, 2], np.full(6, -1), spikes, 3, 2)
    with pytest.raises(ValueError, match="at least 4 steps"):
        render.render_ansi(PATTERN, spikes[:3, 2], np.full(3, -1), spikes[:3], 2, 4)
