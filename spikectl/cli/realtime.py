"""``spikectl realtime``: a controller against the environment paced at 1 kHz, every
decision timed against its deadline (docs/realtime.md)."""

from __future__ import annotations

import io
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro

from spikectl.cli.baseline_policies import environment_setup, generated_split

MAX_RATE_HZ = 1e6
"""The fastest pace the rig accepts (1 µs frames: far beyond any decision's time)."""


@dataclass(frozen=True)
class RealtimeCommand:
    """Play a controller paced at a wall-clock rate; report latency and deadline misses."""

    controller: Annotated[str, tyro.conf.Positional]
    """A run directory, a compiled policy file (.npz), or a registered controller
    (do-nothing, random, identify-and-plan, oracle, witness, ...)."""
    model: Literal["final", "best"] = "final"
    """A run's weights: the final model.pt, or best_model.pt (best validation return)."""
    compiled: bool = False
    """Run a run directory's network as its compiled policy (NumPy/Numba) instead of
    PyTorch."""
    env: str = "spikectl/NeuronControl-v0"
    """The environment (its n_neurons and extensions) for controllers that are not a run
    directory; a run plays its own environment (its params and extensions)."""
    n_neurons: int | None = None
    """Network size of the generated set (default: the environment's, or the run's)."""
    split: Literal["train", "test", "validation"] = "test"
    """Which generated set (make_splits(100, 100, seed=0, n_val=100)) to play."""
    contexts: Path | None = None
    """A saved ContextSet (.npz) to play instead of a generated split."""
    episodes: int = 100
    """Episodes to play: one on each of the set's first contexts (after one untimed
    warm-up episode)."""
    rate_hz: float = 1000.0
    """Frames per second (1000: one step is 1 ms of the neurons' time)."""
    on_miss: Literal["nothing", "late"] = "nothing"
    """A late decision: the frame passes without stimulation (nothing), or the late
    action is applied anyway (late)."""
    cpu: int | None = None
    """Pin the rig to this CPU core (an idle one gives the truest latencies)."""
    torch_threads: int = 1
    """PyTorch threads of a PyTorch controller (1: one core, like the rig)."""
    out: Path | None = None
    """Write every decision (episode, step, latency_ms, missed) to this CSV."""
    overwrite: bool = False
    """Replace an existing --out file (otherwise refused before any work)."""


def realtime(command: RealtimeCommand) -> None:
    """Print the median, p99 and max decision time, the misses and the mean return."""
    from spikectl.cli.output import claimed_outputs
    from spikectl.training.config import MAX_TORCH_THREADS

    for flag, value, least, most in (("--episodes", command.episodes, 1, None),
                                     ("--n-neurons", command.n_neurons, 2, None),
                                     ("--torch-threads", command.torch_threads, 1,
                                      MAX_TORCH_THREADS)):  # fmt: skip
        if value is not None and value < least:
            raise ValueError(f"{flag} must be an integer >= {least}, got {value}")
        if value is not None and most is not None and value > most:
            raise ValueError(f"{flag} must be an integer in {least}..{most}, got {value}")
    if not 0 < command.rate_hz <= MAX_RATE_HZ:
        raise ValueError(
            f"--rate-hz must be a number in (0, {MAX_RATE_HZ:g}], got {command.rate_hz}"
        )
    with claimed_outputs([("--out", command.out)], command.overwrite):
        play_and_write(command)


def play_and_write(command: RealtimeCommand) -> None:
    """Play the rig, print its summary and write --out (claimed by the caller)."""
    from spikectl.cli.output import Printer
    from spikectl.contexts import ContextSet
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.envs.realtime import run_realtime
    from spikectl.training.loaders import load_controller

    print = Printer()  # the decisions are written even if the reader of stdout goes away
    if command.cpu is not None:
        allowed = sorted(os.sched_getaffinity(0))
        if command.cpu not in allowed:
            raise ValueError(f"--cpu {command.cpu}: this process may run on cores {allowed}")
        os.sched_setaffinity(0, {command.cpu})
    source = Path(command.controller)
    config, params, episode_length = None, None, 60
    if source.is_dir():
        from spikectl.training.run_files import read_config

        config = read_config(source)
        params, extensions = config.env.params, config.env.extensions
        n_neurons = command.n_neurons or config.env.n_neurons
        episode_length = config.env.episode_length
    else:
        kwargs, extensions = environment_setup(command.env)
        n_neurons = command.n_neurons or kwargs.get("n_neurons") or 8
    if command.contexts is not None:
        context_set = ContextSet.load(command.contexts)
        where = str(command.contexts)
    else:
        context_set = generated_split(
            command.split, n_neurons, extensions.context_part(), episode_length, params
        )
        where = f"the generated {command.split} set ({n_neurons} neurons, seed 0)"
    if config is not None:
        from spikectl.training.run_sets import check_trained_params

        check_trained_params(context_set, config, str(source), where)
        if context_set.episode_length != episode_length:
            raise ValueError(
                f"--contexts {command.contexts} have episodes of {context_set.episode_length} "
                f"steps; {source} was trained on {episode_length}"
            )
    if command.episodes > len(context_set):
        raise ValueError(f"--episodes {command.episodes}: {where} has {len(context_set)} contexts")
    env = NeuronControlEnv(contexts=context_set, extensions=extensions.environment_part())
    controller = load_controller(command.controller, model=command.model,
                                 compiled=command.compiled, env=env)  # fmt: skip
    if "torch" in sys.modules:  # a PyTorch controller (the others never import it)
        sys.modules["torch"].set_num_threads(command.torch_threads)
    run_realtime(env, controller, [0], command.rate_hz, command.on_miss)  # warm-up
    report = run_realtime(env, controller, range(command.episodes), command.rate_hz,
                          command.on_miss)  # fmt: skip
    summary = report.summary()
    period_ms = 1e3 / command.rate_hz
    print(f"{command.episodes} episodes on {where}; {type(controller).__name__} paced at "
          f"{command.rate_hz:g} Hz (deadline {period_ms:g} ms)")  # fmt: skip
    print(f"decision time: median {summary['median_ms']:.3f} ms, p99 {summary['p99_ms']:.3f} "
          f"ms, max {summary['max_ms']:.3f} ms")  # fmt: skip
    late = "did nothing" if command.on_miss == "nothing" else "acted late"
    print(f"deadline misses: {summary['misses']} of {report.missed.size} "
          f"({100 * summary['miss_fraction']:.2f}%); mean return {summary['mean_return']:.3f} "
          f"(misses {late})")  # fmt: skip
    if command.out is not None:
        print(f"wrote {write_decisions(report, command.out, replace=command.overwrite)}")
    print.finish()


def write_decisions(report, path: Path, replace: bool = True) -> Path:
    """Every decision of a rig run as CSV (episode, step, latency_ms, missed), atomically
    (``replace=False``: never over an existing file)."""
    from spikectl.files import atomic_write_text

    steps = report.latencies_s.size // report.returns.size
    buffer = io.StringIO()
    buffer.write("episode,step,latency_ms,missed\n")
    for index, (latency, missed) in enumerate(zip(report.latencies_s, report.missed,
                                                  strict=True)):  # fmt: skip
        buffer.write(f"{index // steps},{index % steps},{latency * 1e3:.6f},{int(missed)}\n")
    return atomic_write_text(path, buffer.getvalue(), replace)
