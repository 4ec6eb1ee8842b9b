"""The real-time rig (spikectl.envs.realtime, docs/realtime.md): pacing, deadline misses
and what a miss does. Timing assertions are one-sided (the machine may be busy)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from spikectl.contexts import make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.realtime import decision_times, run_realtime


@pytest.fixture(scope="module")
def env() -> NeuronControlEnv:
    test = make_splits(n_train=1, n_test=3, n_neurons=5, episode_length=20)[1]
    return NeuronControlEnv(contexts=test)


class Recorder:
    """Stimulates the lowest legal neuron, sleeping ``slow_s`` on every ``slow_every``-th
    step; records the last_action each observation reports."""

    def __init__(self, slow_every: int = 0, slow_s: float = 0.0) -> None:
        self.slow_every, self.slow_s = slow_every, slow_s
        self.seen: list[int] = []
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1

    def act(self, observation, info) -> int:
        self.seen.append(int(observation["last_action"]))
        if self.slow_every and int(observation["step"]) % self.slow_every == self.slow_every - 1:
            time.sleep(self.slow_s)
        return int(np.flatnonzero(info["action_mask"][1:])[0])


def test_the_rig_paces_every_step_and_times_every_decision(env):
    controller = Recorder()
    start = time.perf_counter()
    report = run_realtime(env, controller, [0, 1], rate_hz=500.0)
    elapsed = time.perf_counter() - start
    assert controller.resets == 2
    assert report.latencies_s.shape == report.missed.shape == (40,)
    assert report.returns.shape == (2,)
    assert elapsed >= 2 * 19 / 500.0  # never faster than the clock: 19 waits per episode
    assert (report.latencies_s > 0).all()
    summary = report.summary()
    assert summary["median_ms"] <= summary["p99_ms"] <= summary["max_ms"]
    assert summary["misses"] == report.misses


def test_a_missed_deadline_stimulates_nothing_unless_late_actions_are_allowed(env):
    # Every 4th decision sleeps 5 ms, five periods at 1 kHz: always a miss.
    slow = Recorder(slow_every=4, slow_s=0.005)
    report = run_realtime(env, slow, [0], rate_hz=1000.0)
    steps = np.arange(20)
    slow_steps = steps % 4 == 3
    assert report.missed[slow_steps].all()
    # The frame after a missed decision reports "nothing" as the last action.
    after_miss = np.flatnonzero(report.missed[:-1]) + 1
    assert all(slow.seen[k] == -1 for k in after_miss)
    late = Recorder(slow_every=4, slow_s=0.005)
    report = run_realtime(env, late, [0], rate_hz=1000.0, on_miss="late")
    assert report.missed[slow_steps].all()
    assert all(late.seen[k] != -1 for k in np.flatnonzero(report.missed[:-1]) + 1)


def test_bad_arguments_are_refused(env):
    with pytest.raises(ValueError, match="rate_hz"):
        run_realtime(env, Recorder(), [0], rate_hz=0)
    with pytest.raises(ValueError, match="on_miss"):
        run_realtime(env, Recorder(), [0], on_miss="skip")
    with pytest.raises(ValueError, match="at least one"):
        run_realtime(env, Recorder(), [])


class Spinner(Recorder):
    """Busy for ``spin_s`` of CPU on every ``slow_every``-th step, asleep for ``sleep_s``
    on every step: the decision clock counts the first and not the second."""

    def __init__(self, slow_every: int, spin_s: float, sleep_s: float = 0.0) -> None:
        super().__init__()
        self.slow_every, self.spin_s, self.sleep_s = slow_every, spin_s, sleep_s

    def act(self, observation, info) -> int:
        if int(observation["step"]) % self.slow_every == 0:
            until = time.thread_time() + self.spin_s
            while time.thread_time() < until:
                pass
        time.sleep(self.sleep_s)
        return super().act(observation, info)


def test_decision_times_count_each_decision_s_own_cpu(env):
    """One time per decision (episodes x steps); a decision that spins 3 ms of CPU takes
    at least that; 2 ms of sleep is not CPU and is not counted."""
    times = decision_times(env, Spinner(slow_every=5, spin_s=3e-3, sleep_s=2e-3), [0, 1])
    assert times.shape == (2 * env.episode_length,)
    slow = np.zeros(env.episode_length, dtype=bool)
    slow[::5] = True
    slow = np.tile(slow, 2)
    assert times[slow].min() >= 3e-3
    assert np.median(times[~slow]) < 1e-3  # the sleep: 2 ms of wall time each


def test_decision_times_play_the_episodes_the_rig_plays(env):
    """Unpaced, the same actions and resets as the rig's episodes on the same contexts."""
    timed, paced = Recorder(), Recorder()
    decision_times(env, timed, [2, 0], seed=7)
    # "late": a deadline missed on a loaded machine must not turn an action into nothing.
    run_realtime(env, paced, [2, 0], rate_hz=200.0, on_miss="late", seed=7)
    assert timed.seen == paced.seen and timed.resets == paced.resets == 2
    with pytest.raises(ValueError, match="contexts must name at least one context index"):
        decision_times(env, Recorder(), [])
