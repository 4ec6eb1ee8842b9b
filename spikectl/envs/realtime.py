"""A real-time rig: a controller plays the environment paced at a wall-clock rate (1 kHz
by default: one step is 1 ms of the neurons' time), and every decision is timed against
its deadline (issue 24; docs/realtime.md).

A controller is anything with ``reset()`` and ``act(observation, info) -> int``
(:mod:`spikectl.envs.controller`; ``spikectl.load_controller`` builds any of the
library's, and ``spikectl realtime`` runs this rig from the command line). Frame k "arrives" at tick
k = start + k / rate; the controller's decision on it must be ready before tick k + 1.
Its latency is measured from the tick, so a decision that overruns delays the next
frame's processing too (the frames queue up, as on a rig that reads every frame). A
decision later than one period is a deadline miss; with ``on_miss="nothing"`` (the
default) the stimulator did nothing in that frame, so the environment steps with -1
instead, and the return shows what the misses cost.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spikectl.envs.controller import Controller
from spikectl.neuron.simulator import DO_NOTHING

ON_MISS = ("nothing", "late")
"""What a missed deadline does: the frame passes with no stimulation (``nothing``), or
the late action is applied anyway (``late``, as if the clock had waited)."""


@dataclass(frozen=True)
class RealtimeReport:
    """Decisions of one paced run, in order (every step of every episode)."""

    rate_hz: float
    latencies_s: np.ndarray
    """[steps] each decision's time from its frame's tick to the action, seconds."""
    missed: np.ndarray
    """[steps] bool: the decision came later than one period after its tick."""
    returns: np.ndarray
    """[episodes] each episode's return, misses included."""

    @property
    def misses(self) -> int:
        return int(self.missed.sum())

    def summary(self) -> dict[str, float]:
        """Median, p99 and max latency (ms), misses, their fraction, and the mean return."""
        ms = self.latencies_s * 1e3
        return {
            "median_ms": float(np.median(ms)),
            "p99_ms": float(np.percentile(ms, 99)),
            "max_ms": float(ms.max()),
            "misses": self.misses,
            "miss_fraction": float(self.missed.mean()),
            "mean_return": float(self.returns.mean()),
        }


def run_realtime(
    env: Any,
    controller: Controller,
    contexts: Sequence[int],
    rate_hz: float = 1000.0,
    on_miss: str = "nothing",
    seed: int = 0,
) -> RealtimeReport:
    """Play one episode per context index of ``env`` (a single ``NeuronControlEnv``),
    paced at ``rate_hz``, and time every decision of ``controller`` against its deadline.

    Episode i resets with ``seed + i``; its first frame arrives when the reset returns.
    The rig waits for each tick by spinning on ``time.perf_counter_ns``, never sleeping:
    it keeps its core (and the controller's weights in that core's caches) as a rig's
    control loop would. A sleeping loop hands the core to other processes between
    frames, whose data then evict the controller's; that doubled the compiled policy's
    median decision time (docs/realtime.md).
    """
    if not isinstance(rate_hz, int | float) or not rate_hz > 0:
        raise ValueError(f"rate_hz must be a positive number, got {rate_hz!r}")
    if on_miss not in ON_MISS:
        raise ValueError(f"on_miss must be one of {ON_MISS}, got {on_miss!r}")
    contexts = list(contexts)
    if not contexts:
        raise ValueError("contexts must name at least one context index")
    period = round(1e9 / rate_hz)  # ns
    latencies: list[int] = []
    missed: list[bool] = []
    returns = np.zeros(len(contexts))
    for episode, context in enumerate(contexts):
        controller.reset()
        observation, info = env.reset(seed=seed + episode, options={"context": int(context)})
        tick = time.perf_counter_ns()
        done = False
        while not done:
            action = controller.act(observation, info)
            latency = time.perf_counter_ns() - tick
            late = latency > period
            latencies.append(latency)
            missed.append(late)
            if late and on_miss == "nothing":
                action = DO_NOTHING
            observation, reward, terminated, truncated, info = env.step(action)
            returns[episode] += reward
            done = terminated or truncated
            tick += period
            _wait_until(tick)
    return RealtimeReport(
        rate_hz=float(rate_hz),
        latencies_s=np.array(latencies, dtype=np.float64) * 1e-9,
        missed=np.array(missed, dtype=bool),
        returns=returns,
    )


def decision_times(
    env: Any, controller: Controller, contexts: Sequence[int], seed: int = 0
) -> np.ndarray:
    """[decisions] the CPU seconds each of ``controller``'s decisions takes, unpaced: one
    episode per context index of ``env`` (a single ``NeuronControlEnv``; episode i resets
    with ``seed + i``), each ``act`` timed alone by the deciding thread's CPU clock.

    On an idle core that is the decision's wall time; on a busy machine it leaves out the
    time other processes hold the core, so the numbers of one controller compare across
    runs (a controller's own worker threads are not counted: time it with one thread, as
    the rig does). :func:`run_realtime` measures what a paced loop adds to it."""
    contexts = list(contexts)
    if not contexts:
        raise ValueError("contexts must name at least one context index")
    times: list[int] = []
    for episode, context in enumerate(contexts):
        controller.reset()
        observation, info = env.reset(seed=seed + episode, options={"context": int(context)})
        done = False
        while not done:
            started = time.thread_time_ns()
            action = controller.act(observation, info)
            times.append(time.thread_time_ns() - started)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
    return np.array(times, dtype=np.float64) * 1e-9


def _wait_until(tick_ns: int) -> None:
    while time.perf_counter_ns() < tick_ns:
        pass
