"""``spikectl benchmark``: a controller on the frozen suite's tasks (docs/benchmark.md)."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import tyro


@dataclass(frozen=True)
class BenchmarkCommand:
    """Score a controller on the frozen benchmark suite: raw and normalised returns."""

    controller: Annotated[str, tyro.conf.Positional]
    """A run directory, a compiled policy file (.npz), or a registered controller
    (do-nothing, random, identify-and-plan, oracle, witness, ...)."""
    task: tuple[str, ...] = ("all",)
    """The suite version's tasks to play (v1: paper n16 n32 noise1 noise2 noise4 hidden25
    stochastic heterogeneous background), or all."""
    suite: int = 1
    """The suite version (results of two versions do not compare)."""
    split: Literal["test", "validation"] = "test"
    """Which frozen set to play: report on test, choose settings on validation."""
    model: Literal["final", "best"] = "final"
    """A run's weights: the final model.pt, or best_model.pt (best validation return)."""
    compiled: bool = False
    """Run a run directory's network as its compiled policy instead of PyTorch."""
    per_environment: bool = False
    """Play a run's PyTorch network on each context alone, as `spikectl realtime RUN`
    does: its actions on every CPU (by default one batched forward per task)."""
    random_seeds: int = 10
    """Seeds 0 .. N-1 of the random controller (its score is the mean over them); the
    other controllers are deterministic and play once."""
    torch_threads: int = 1
    """PyTorch threads of a run's network (CPU seconds are counted over all threads)."""
    decision_episodes: int = 10
    """Episodes on the set's first networks, after one untimed warm-up episode, whose every
    decision is timed alone on one environment by the deciding thread's CPU clock: the
    rows' decision_p50_ms and decision_p99_ms (0: not timed, those columns stay empty)."""
    out: Path | None = None
    """Write one CSV row per task (raw, normalised, references, CPU seconds) here."""
    per_network: Path | None = None
    """Write one CSV row per task and network (its return) here: what a network-by-network
    comparison of two controllers reads."""
    overwrite: bool = False
    """Replace an existing --out or --per-network file (otherwise refused before any work)."""


MAX_RANDOM_SEEDS = 1000
"""The most seeds of the random controller (each plays the whole suite once more)."""
CSV_FIELDS = (
    "suite_version", "task", "split", "controller", "model", "seeds", "mean_return",
    "standard_error", "sd_over_seeds", "normalised", "do_nothing", "oracle", "cpu_seconds",
    "contexts", "trained_on", "composition", "decision_p50_ms", "decision_p99_ms",
)  # fmt: skip
REFERENCE_CONTROLLERS = ("do-nothing", "oracle")
"""The registered controllers that are the normalised score's 0 and 1
(:func:`~spikectl.experiments.suite.reference_scores`, in that order)."""
PER_NETWORK_FIELDS = ("suite_version", "task", "split", "controller", "model", "context", "return",
                      "composition")  # fmt: skip
"""``composition``: the name of the composition a composed controller played on the task
(identify-and-plan's, :mod:`spikectl.planning.named`); empty for the others."""


def benchmark(command: BenchmarkCommand) -> None:
    """Print the controller's mean return and normalised score on each task."""
    from spikectl.cli.output import claimed_outputs
    from spikectl.training.config import MAX_TORCH_THREADS

    if not 1 <= command.random_seeds <= MAX_RANDOM_SEEDS:
        raise ValueError(f"--random-seeds must be an integer in 1..{MAX_RANDOM_SEEDS}, "
                         f"got {command.random_seeds}")  # fmt: skip
    if not 1 <= command.torch_threads <= MAX_TORCH_THREADS:
        raise ValueError(f"--torch-threads must be an integer in 1..{MAX_TORCH_THREADS}, "
                         f"got {command.torch_threads}")  # fmt: skip
    # Refused before the episodes, not after: nothing is overwritten that should not be,
    # and a second benchmark writing the same file meanwhile is refused.
    outputs = (("--out", command.out), ("--per-network", command.per_network))
    with claimed_outputs(outputs, command.overwrite):
        score_and_write(command)


def score_and_write(command: BenchmarkCommand) -> None:
    """Play the suite, print the table and write the output files (claimed by the caller)."""
    from spikectl.cli.output import Printer
    from spikectl.experiments import suite

    if not Path(command.controller).is_dir():
        for flag, given in (("--model", command.model != "final"),
                            ("--compiled", command.compiled)):  # fmt: skip
            if given:
                raise ValueError(f"{flag} chooses among a run directory's networks; "
                                 f"{command.controller} is not a run directory")  # fmt: skip
    print = Printer()  # results are written even if the reader of stdout goes away
    version = suite.suite_version(command.suite)  # an unknown one: one line naming those there are
    names = list(version.names()) if "all" in command.task else list(dict.fromkeys(command.task))
    if not names:
        raise ValueError("--task: give at least one task, or all")
    if not 0 <= command.decision_episodes <= version.set_size:
        raise ValueError(f"--decision-episodes must be an integer in 0..{version.set_size} "
                         f"(the set's networks), got {command.decision_episodes}")  # fmt: skip
    for name in names:
        version.task(name)  # an unknown task is refused before anything is played
    make = controller_factory(command, names)
    # A task the controller cannot play is found before any episode: named, it is refused
    # in one line; under "all" it is skipped with that line, and the other tasks are played.
    skipped = {}
    for name in names:
        why = task_refusal(make, name, command.split, version.number)
        if why is not None and "all" not in command.task:
            raise ValueError(f"{command.controller} cannot play task {name!r}: {why}")
        if why is not None:
            skipped[name] = why
    names = [name for name in names if name not in skipped]
    origin = training_task(command)
    seeds = command.random_seeds if stochastic(command.controller) else 1
    print(f"benchmark suite v{version.number}, {command.split} sets "
          f"({version.set_size} contexts each, environment seed {version.env_seed}); "
          f"controller {command.controller}"
          + (f" (mean over seeds 0..{seeds - 1})" if seeds > 1 else "")
          + (f"; trained on task {origin!r}" if origin else ""))  # fmt: skip
    print(f"{'task':<15}{'mean return':>18}{'normalised':>12}{'do nothing':>12}"
          f"{'oracle':>9}{'CPU s':>9}{'p50 ms':>9}{'p99 ms':>9}")  # fmt: skip
    for name, why in skipped.items():
        print(f"{name:<15}skipped: {command.controller} cannot play it ({why})")
    rows, per_network, normalised = [], [], {}
    for name in names:
        if command.controller in REFERENCE_CONTROLLERS:  # played once, for the references too
            which = REFERENCE_CONTROLLERS.index(command.controller)
            result = suite.reference_scores(name, command.split, version.number)[which]
            composition = ""
        else:
            played: list[Any] = []  # the controllers made, to name the composition they played
            result = suite.score(name, command.split, recorded(make(name), played), seeds,
                                 version.number)
            composition = composition_of(played[0])
        per_network += [
            {"suite_version": version.number, "task": name, "split": command.split,
             "controller": command.controller, "model": model_label(command),
             "context": index, "return": repr(float(value)), "composition": composition}
            for index, value in enumerate(result.returns)
        ]  # fmt: skip
        nothing, oracle = suite.references(name, command.split, version.number)
        normalised[name] = suite.normalise(result.mean_return, nothing, oracle)
        sd = float(result.seed_means.std(ddof=1)) if seeds > 1 else float("nan")
        raw = f"{result.mean_return:.3f}" + (f" +- {sd:.3f}" if seeds > 1 else "")
        p50, p99 = decision_percentiles(make, name, command, version.number)
        print(f"{name:<15}{raw:>18}{normalised[name]:>12.3f}{nothing:>12.3f}{oracle:>9.3f}"
              f"{result.cpu_seconds:>9.2f}{p50 or '-':>9}{p99 or '-':>9}")  # fmt: skip
        rows.append({
            "suite_version": version.number, "task": name, "split": command.split,
            "controller": command.controller, "model": model_label(command), "seeds": seeds,
            "mean_return": f"{result.mean_return:.6f}",
            "standard_error": f"{result.standard_error:.6f}",
            "sd_over_seeds": "" if seeds == 1 else f"{sd:.6f}",
            "normalised": f"{normalised[name]:.6f}", "do_nothing": f"{nothing:.6f}",
            "oracle": f"{oracle:.6f}", "cpu_seconds": f"{result.cpu_seconds:.3f}",
            "contexts": len(result.returns), "trained_on": origin or "",
            "composition": composition, "decision_p50_ms": p50, "decision_p99_ms": p99,
        })  # fmt: skip
    if len(names) > 1:
        print(f"mean normalised score over {len(names)} tasks: "
              f"{suite.mean_normalised(normalised):.3f}")  # fmt: skip
    written = []
    if command.out is not None:
        written.append(write_rows(rows, command.out, replace=command.overwrite))
    if command.per_network is not None:
        written.append(write_rows(per_network, command.per_network, PER_NETWORK_FIELDS,
                                  replace=command.overwrite))  # fmt: skip
    for path in written:
        print(f"wrote {path}")
    print.finish()


def task_refusal(make: Any, name: str, split: str, version: int) -> str | None:
    """Why the controller ``make(name)`` makes cannot play task ``name``, or None
    (:func:`~spikectl.envs.controller.first_decision_refusal` on the task's set)."""
    from spikectl.envs.controller import first_decision_refusal
    from spikectl.envs.env import NeuronControlEnv
    from spikectl.experiments import suite

    env = NeuronControlEnv(contexts=suite.load_split(name, split, version),
                           extensions=suite.task(name, version).extensions)  # fmt: skip
    return first_decision_refusal(env, lambda: make(name)(0))


def decision_percentiles(make: Any, name: str, command: BenchmarkCommand,
                         version: int) -> tuple[str, str]:  # fmt: skip
    """The median and 99th percentile (ms, as written) of the CPU time of each decision of
    ``make(name)(0)`` over ``command.decision_episodes`` episodes of task ``name``, one
    environment, unpaced (:func:`~spikectl.envs.realtime.decision_times`); ("", "") when
    not timed."""
    if command.decision_episodes == 0:
        return "", ""
    import numpy as np

    from spikectl.envs.env import NeuronControlEnv
    from spikectl.envs.realtime import decision_times
    from spikectl.experiments import suite

    env = NeuronControlEnv(contexts=suite.load_split(name, command.split, version),
                           extensions=suite.task(name, version).extensions)  # fmt: skip
    seed = suite.suite_version(version).env_seed
    controller = make(name)(0)
    decision_times(env, controller, [0], seed)  # warm-up: compilation, first allocations
    ms = decision_times(env, controller, range(command.decision_episodes), seed) * 1e3
    env.close()
    return f"{np.percentile(ms, 50):.4f}", f"{np.percentile(ms, 99):.4f}"


def training_task(command: BenchmarkCommand) -> str | None:
    """The suite task a run directory trained on (None for anything else, or a run
    trained off the suite): on any other task its scores are a transfer."""
    source = Path(command.controller)
    if not source.is_dir():
        return None
    from spikectl.contexts import ContextSet
    from spikectl.experiments import suite
    from spikectl.training.run_files import read_config
    from spikectl.training.run_sets import TRAIN_FILE

    if not (source / TRAIN_FILE).is_file():
        return None
    return suite.trained_on(read_config(source), ContextSet.load(source / TRAIN_FILE),
                            command.suite)  # fmt: skip


def recorded(make: Any, played: list[Any]) -> Any:
    """``make`` (seed -> controller), appending each controller it makes to ``played``."""

    def make_and_keep(seed: int) -> Any:
        played.append(make(seed))
        return played[-1]

    return make_and_keep


def composition_of(controller: Any) -> str:
    """The name of the composition ``controller`` plays ("" where it is not composed)."""
    return str(getattr(getattr(controller, "composition", None), "name", ""))


def model_label(command: BenchmarkCommand) -> str:
    """Which weights of a run played ("" for the other controllers)."""
    if not Path(command.controller).is_dir():
        return ""
    if command.compiled:
        return command.model + " compiled"
    return command.model + (" per-environment" if command.per_environment else "")


def stochastic(controller: str) -> bool:
    """Whether ``controller`` is a registered controller whose seed changes what it does."""
    from spikectl.training.loaders import CONTROLLERS

    return controller in CONTROLLERS and CONTROLLERS.load(controller).stochastic


def controller_factory(command: BenchmarkCommand, names: list[str]) -> Any:
    """task name -> (seed -> a fresh controller for that task); refuses at once a run
    that cannot play one of ``names`` (another neuron model, or a fixed-size network
    on another n)."""
    from spikectl.experiments import suite
    from spikectl.training.loaders import CONTROLLERS, load_agent, load_controller

    source = Path(command.controller)
    version = command.suite
    if command.controller in CONTROLLERS:

        def named(name: str):
            from spikectl.envs.env import NeuronControlEnv

            contexts = suite.load_split(name, command.split, version)
            extensions = suite.task(name, version).extensions
            env = NeuronControlEnv(contexts=contexts, extensions=extensions)
            return lambda seed: load_controller(command.controller, env=env, seed=seed)

        return named
    if source.is_dir():
        from spikectl.training.run_files import read_config

        config = read_config(source)
        for name in names:
            try:
                suite.check_run_fits(config, name, version)
            except ValueError as error:
                raise ValueError(f"{source} cannot play task {name!r}: {error}") from None
        import torch

        torch.set_num_threads(command.torch_threads)

        def trained(name: str):
            from spikectl.agents.greedy import GreedyController

            task = suite.task(name, version)
            network = load_agent(source, n_neurons=task.n_observed, model=command.model)
            if command.compiled:
                from spikectl.agents.compiled import CompiledPolicy

                policy = CompiledPolicy.from_network(network)
                return lambda seed: policy
            return lambda seed: GreedyController(network, per_environment=command.per_environment)

        return trained
    controller = load_controller(command.controller)  # a compiled policy file, or refused
    return lambda name: lambda seed: controller


def write_rows(
    rows: list[dict], path: Path, fields: tuple[str, ...] = CSV_FIELDS, replace: bool = True
) -> Path:
    """The rows as CSV, atomically (``replace=False``: never over an existing file)."""
    from spikectl.files import atomic_write_text

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return atomic_write_text(path, buffer.getvalue(), replace)
