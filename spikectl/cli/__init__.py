"""The ``spikectl`` command line: thin wrappers, one typed config per subcommand (tyro)."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import re
import sys
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
import tyro

from spikectl.agents import AgentSizes
from spikectl.contexts import ContextSet, make_splits
from spikectl.experiments.sweep import SweepError
from spikectl.files import FileWriteError, make_dirs, write_json
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.training.config import AgentConfig, EnvConfig, Experiment, TrainConfig
from spikectl.training.learners import DQNConfig
from spikectl.training.presets import PRESET_HELP, PRESETS
from spikectl.training.run_files import RunDirError

USER_ERRORS = (ValueError, FileNotFoundError, FileWriteError, RunDirError, SweepError)
"""What the commands raise for bad input or a bad file system: reported in one line with
exit status 2. ValueError covers every validation error of the library (ContextFileError,
TooLargeError, config and argument checks); anything else is a bug and keeps its traceback."""


@dataclass(frozen=True)
class DemoConfig:
    """Generate contexts, score the reference policies on them and save an episode raster."""

    out_dir: Path = Path("runs/demo")
    """Where the context sets, results.json and raster.png are written."""
    n_train: int = 100
    """Training contexts."""
    n_test: int = 100
    """Unseen test contexts (no topology shared with the training set)."""
    n_neurons: int = 8
    """Neurons per network."""
    episode_length: int = 60
    """Steps (ms) per episode."""
    seed: int = 0
    """Seed of the context generation and of the random policy."""


def demo(config: DemoConfig) -> dict[str, dict[str, float]]:
    """A 3-second tour: score do-nothing, random and witness policies; save an episode raster."""
    from spikectl.envs.rollout import (
        do_nothing_policy,
        evaluate_policy,
        make_random_policy,
        make_witness_policy,
    )
    from spikectl.experiments.figures import plot_episode_raster

    train, test = make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length, config.seed
    )
    make_dirs(config.out_dir)
    train.save(config.out_dir / "train_contexts.npz")
    test.save(config.out_dir / "test_contexts.npz")
    results: dict[str, dict[str, float]] = {}
    print(
        f"{len(train)} training and {len(test)} unseen test networks of {config.n_neurons} "
        f"neurons, episodes of {config.episode_length} steps"
    )
    print(f"{'policy':<12}{'train':>10}{'test':>10}")
    random_episodes = None
    for name in ("do-nothing", "random", "witness"):
        row = {}
        for split, contexts in (("train", train), ("test", test)):
            policy = {
                "do-nothing": do_nothing_policy,
                "random": make_random_policy(config.seed),
                "witness": make_witness_policy(contexts),
            }[name]
            episodes = evaluate_policy(contexts, policy)
            row[split] = float(episodes.returns.mean())
            if name == "random" and split == "test":
                random_episodes = episodes
        results[name] = row
        print(f"{name:<12}{row['train']:>10.3f}{row['test']:>10.3f}")
    context = test[0]
    raster = plot_episode_raster(
        context.pattern,
        random_episodes.actions[0],
        random_episodes.spikes[0],
        context.target,
        config.out_dir / "raster.png",
        title=f"random policy on unseen test network 0: return {random_episodes.returns[0]:.3f}",
    )
    write_json(config.out_dir / "results.json", {"config": asdict(config), "returns": results})
    print(f"wrote {raster} and {config.out_dir / 'results.json'}")
    return results


@dataclass(frozen=True)
class ContextsConfig:
    """Generate a training and a test context set and save them, or describe a saved set."""

    action: Literal["generate", "show"] = "generate"
    """generate: make and save train/test sets; show: describe the file in --path."""
    out_dir: Path = Path("contexts")
    """Where generate writes train_contexts.npz and test_contexts.npz."""
    path: Path | None = None
    """The set file that show describes."""
    n_train: int = 100
    """Training contexts."""
    n_test: int = 100
    """Test contexts."""
    n_neurons: int = 8
    """Neurons per network."""
    episode_length: int = 60
    """Steps per episode."""
    seed: int = 0
    """Generation seed."""
    overwrite: bool = False
    """Replace existing train_contexts.npz / test_contexts.npz in --out-dir."""


def contexts(config: ContextsConfig) -> None:
    """Generate and save context sets, or print what a saved set holds."""
    if config.action == "show":
        if config.path is None:
            raise ValueError("--path: show needs --path FILE")
        described = ContextSet.load(config.path)
        spikes = [int(context.pattern.sum()) for context in described]
        print(f"{config.path}: {described!r}")
        print(f"checksum {described.checksum()}")
        print(
            f"spikes per pattern: mean {np.mean(spikes):.2f}, min {min(spikes)}, max {max(spikes)}"
        )
        print(f"targets: {[context.target for context in described]}")
        return
    paths = {name: config.out_dir / f"{name}_contexts.npz" for name in ("train", "test")}
    existing = [str(path) for path in paths.values() if path.exists()]
    if existing and not config.overwrite:
        raise ValueError(
            f"--out-dir: {' and '.join(existing)} exist(s): pass --overwrite to replace, or "
            "choose another --out-dir"
        )
    train, test = make_splits(
        config.n_train, config.n_test, config.n_neurons, config.episode_length, config.seed
    )
    for name, contexts_set in (("train", train), ("test", test)):
        path = contexts_set.save(paths[name])
        print(f"wrote {path}: {contexts_set!r}")


@dataclass(frozen=True)
class TrainCommand:
    """Train an agent: the preset's settings, then every flag's."""

    config: Annotated[Experiment, tyro.conf.arg(name="")]
    preset: tyro.conf.Suppress[str] = "quick"
    """The preset the defaults come from (the subcommand)."""
    run_dir: Path | None = None
    """Run directory (default runs/ARCH-PRESET-seedSEED); must be new unless resuming."""
    resume: Path | None = None
    """Continue the interrupted run (or seed group) in this directory (its saved config is used)."""
    seeds: tuple[int, ...] | None = None
    """Train these seeds as one group in one process (RUN_DIR/seed=S each; each seed
    exactly as if trained alone)."""
    stacked: bool = False
    """With --seeds: compute the seeds as one stacked computation (pays on a GPU; equal
    to the seeds alone up to floating-point rounding)."""


def torch_threads() -> int:
    import torch

    return torch.get_num_threads()


def train(command: TrainCommand) -> None:
    """Train (or resume) one run or a seed group, then print the returns against the
    baselines (for a group, each seed's)."""
    from spikectl.training.group import GROUP_FILE, group_configs, group_is_stacked, seed_dirs
    from spikectl.training.run import train_runs
    from spikectl.training.run_files import read_config

    resume, stacked = command.resume is not None, command.stacked
    if stacked and command.seeds is None and not resume:
        raise ValueError("--stacked: stacking computes a seed group; give --seeds too")
    if resume and (command.resume / GROUP_FILE).exists():
        group_dir = command.resume
        configs, run_dirs = group_configs(group_dir)
        stacked = group_is_stacked(group_dir)
    elif resume:
        group_dir, run_dirs = None, [command.resume]
        configs = [read_config(command.resume)]
    elif command.seeds is not None:
        config, seeds = command.config, list(command.seeds)
        if not seeds:
            raise ValueError("--seeds needs at least one seed")
        label = "-".join(str(seed) for seed in seeds)
        group_dir = command.run_dir or Path(
            f"runs/{config.agent.arch}-{command.preset}-seeds{label}"
        )
        configs, run_dirs = [config.with_seed(seed) for seed in seeds], seed_dirs(group_dir, seeds)
    else:
        config, group_dir = command.config, None
        configs = [config]
        run_dirs = [command.run_dir or Path(
            f"runs/{config.agent.arch}-{command.preset}-seed{config.train.seed}"
        )]  # fmt: skip
    if group_dir is None:
        print(f"run directory: {run_dirs[0]}")
    else:
        how = "stacked" if stacked else "in one process"
        print(f"seed group: {group_dir} ({len(configs)} seeds {how})")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        metrics = train_runs(configs, run_dirs, group_dir, resume=resume, stacked=stacked)
    for warning in caught:
        print(f"spikectl: warning: {warning.message}", file=sys.stderr)
    if group_dir is None:
        _print_run(configs[0], run_dirs[0], metrics[0])
    else:
        _print_group(configs, run_dirs, metrics)


def _print_run(config: Experiment, run_dir: Path, metrics: list[dict]) -> None:
    """A single run's final returns, its baselines and its best network on validation."""
    from spikectl.experiments.figures import plot_learning_curve
    from spikectl.training.run import best_on_validation

    final = metrics[-1]
    baselines = json.loads((run_dir / "baselines.json").read_text())
    curve = plot_learning_curve(
        metrics, baselines, run_dir / "learning_curve.png",
        title=f"{config.agent.arch.upper()}, {final['env_steps']:,} steps",
    )  # fmt: skip
    validation = (
        ""
        if math.isnan(final.get("val_return", math.nan))
        else (f"  (validation {final['val_return']:.3f})")
    )
    print(f"{'':<14}{'train':>8}{'test':>8}")
    print(
        f"{config.agent.arch:<14}{final['train_return']:>8.3f}{final['test_return']:>8.3f}"
        f"{validation}"
    )
    for name in ("do_nothing", "random"):
        row = baselines[name]
        print(f"{name.replace('_', '-'):<14}{row['train']:>8.3f}{row['test']:>8.3f}")
    best = best_on_validation(metrics)
    if best is not None:
        print(
            f"{'best on val.':<14}{best['train_return']:>8.3f}{best['test_return']:>8.3f}"
            f"  (validation {best['val_return']:.3f}, episode {best['episode']:,}: "
            "best_model.pt)"
        )
    minutes, core_minutes = final["wall_time_s"] / 60, final["cpu_time_s"] / 60
    print(
        f"{final['env_steps']:,} environment steps, {final['updates']:,} updates, "
        f"{minutes:.1f} wall minutes ({core_minutes:.1f} core minutes) on "
        f"{config.train.torch_threads or torch_threads()} thread(s)"
    )
    print(f"wrote {run_dir / 'model.pt'}, {run_dir / 'metrics.csv'} and {curve}")


def _print_group(configs: list[Experiment], run_dirs: list[Path], metrics: list[list[dict]]):
    """Each seed's final returns and its best network on validation, and the group's time."""
    from spikectl.training.run import best_on_validation

    print(f"{'seed':<14}{'train':>8}{'test':>8}   best on validation: train, test (episode)")
    for config, rows in zip(configs, metrics, strict=True):
        final, best = rows[-1], best_on_validation(rows)
        chosen = (
            ""
            if best is None
            else f"   {best['train_return']:.3f}, {best['test_return']:.3f} ({best['episode']:,})"
        )
        print(
            f"{config.train.seed:<14}{final['train_return']:>8.3f}{final['test_return']:>8.3f}"
            f"{chosen}"
        )
    final = metrics[0][-1]  # the seeds share the group's clocks
    print(
        f"{len(configs)} x {final['env_steps']:,} environment steps, {final['updates']:,} "
        f"updates each, {final['wall_time_s'] / 60:.1f} wall minutes "
        f"({final['cpu_time_s'] / 60:.1f} core minutes) for the whole group"
    )
    print(f"wrote model.pt and metrics.csv in {', '.join(str(d) for d in run_dirs)}")


@dataclass(frozen=True)
class EvaluateCommand:
    """Evaluate a trained agent greedily on its own sets or on any context set."""

    run_dir: Annotated[Path, tyro.conf.Positional]
    """The run directory of a trained agent."""
    contexts: Path | None = None
    """A saved ContextSet (.npz) to evaluate on instead of the run's train/test sets."""
    model: Literal["final", "best"] = "final"
    """Which weights: the final model.pt, or best_model.pt (best validation return)."""


def evaluate(command: EvaluateCommand) -> None:
    """Print the agent's mean greedy return per split, with its standard error."""
    from spikectl.training.evaluate import evaluate_run

    for result in evaluate_run(command.run_dir, command.contexts, command.model):
        print(
            f"{result.name:<24}{result.mean:.3f} +- {result.standard_error:.3f} "
            f"over {result.returns.size} contexts (do nothing {result.do_nothing:.3f})"
        )


@dataclass(frozen=True)
class SweepCommand:
    """Run a grid of training trials; finished trials are skipped, interrupted ones resumed."""

    sweep_dir: Path = Path("runs/sweep")
    """Where the trials' run directories and sweep.json go."""
    preset: Literal["fig4", "fig5"] | None = None
    """The paper's experiments: fig4 (4 architectures x 10 seeds), fig5 (TDRQN x sizes)."""
    config: Path | None = None
    """A JSON sweep file instead: {"base": PRESET, "overrides": {...}, "grid": {...}}."""
    base: Literal["paper", "quick", "smoke"] | None = None
    """Replace the sweep's base preset (e.g. quick for a laptop-sized reproduction)."""
    seeds: tuple[int, ...] | None = None
    """Replace the grid's seeds."""
    total_env_steps: int | None = None
    """Override the environment steps of every trial."""
    workers: int = 0
    """Trials run at once; 0 means one per CPU core."""
    backend: Literal["local", "ray"] = "local"
    """local: a process pool on this machine; ray: Ray tasks (pip install 'spikectl[ray]')."""
    address: str | None = None
    """Ray cluster address (ray backend); a local Ray instance when not given."""
    group_seeds: bool = False
    """Train the trials that differ only in seed and n_train in one process per group."""


def sweep(command: SweepCommand) -> None:
    """Run the sweep and print each trial's final train and test return."""
    from spikectl.experiments.sweep import PAPER_SWEEPS, Sweep, load_sweep_file, run_sweep

    if (command.preset is None) == (command.config is None):
        raise ValueError("give exactly one of --preset (fig4, fig5) or --config FILE")
    if command.workers < 0:
        raise ValueError(f"--workers must be >= 0 (0: one per CPU core), got {command.workers}")
    if command.config is not None:
        description = load_sweep_file(command.config).to_dict()
        if command.base is not None:
            # --base swaps the preset under the file's own overrides, which stay.
            description = json.loads(command.config.read_text())
            if not isinstance(description.get("base", "quick"), str):
                raise ValueError(
                    f"--base: {command.config} holds a whole base config, not a preset name; "
                    "edit its base or drop --base"
                )
    else:
        description = dict(PAPER_SWEEPS[command.preset])
    description = {**description, "grid": dict(description["grid"])}
    if command.base is not None:
        description["base"] = command.base
    if command.seeds is not None:
        description["grid"]["seed"] = list(command.seeds)
    if command.total_env_steps is not None:
        description["overrides"] = {
            **description.get("overrides", {}), "train.total_env_steps": command.total_env_steps,
        }  # fmt: skip
    run_sweep(
        Sweep.from_dict(description), command.sweep_dir, command.workers or None,
        backend=command.backend, address=command.address, group_seeds=command.group_seeds,
    )  # fmt: skip


@dataclass(frozen=True)
class PlotCommand:
    """Draw Figures 3-5, the results tables and an episode raster of a sweep."""

    sweep_dir: Annotated[Path, tyro.conf.Positional]
    """The sweep directory (as given to spikectl sweep)."""
    out_dir: Path | None = None
    """Where to write them (default SWEEP_DIR/figures)."""


def plot(command: PlotCommand) -> None:
    """Write the figures and tables of a sweep from its saved runs."""
    from spikectl.experiments.plot import plot_sweep

    for path in plot_sweep(command.sweep_dir, command.out_dir):
        print(f"wrote {path}")


@dataclass(frozen=True)
class BaselinesCommand:
    """Score do nothing, random, identify-and-plan, the oracle planner and the witness."""

    split: Literal["train", "test", "validation"] = "test"
    """Which generated set (make_splits(100, 100, seed=0, n_val=100) with the env's
    settings) to play; choose settings on train or validation, report on test."""
    contexts: Path | None = None
    """A saved ContextSet (.npz) to play instead of a generated split."""
    env: str = "spikectl/NeuronControl-v0"
    """A registered environment id: its n_neurons and extensions apply."""
    out: Path = Path("runs/baselines/baselines.csv")
    """Where the per-context CSV is written."""
    random_seeds: int = 10
    """Seeds of the random policy (the table shows mean +- sd over them)."""
    oracle_width: int = 256
    """Beam width of the oracle planner."""
    identify_width: int = 32
    """Beam width of identify-and-plan's re-plans."""
    observation_noise_mV: float | None = None
    """Measurement noise sigma (mV) instead of the environment's."""
    hidden_fraction: float | None = None
    """Fraction of hidden neurons instead of the environment's (generated sets only)."""


def baselines(command: BaselinesCommand) -> None:
    """Print the table of training-free controllers and write a per-context CSV."""
    from dataclasses import replace

    import gymnasium

    from spikectl.neuron.extensions import Extensions
    from spikectl.planning import IdentifyAndPlan
    from spikectl.planning.baselines import run_baselines

    if command.env not in gymnasium.registry:
        raise ValueError(f"unknown environment id {command.env!r}")
    kwargs = dict(gymnasium.spec(command.env).kwargs)
    extensions = Extensions.coerce(kwargs.get("extensions"))
    overrides = {
        name: value
        for name, value in (("observation_noise_mV", command.observation_noise_mV),
                            ("hidden_fraction", command.hidden_fraction))
        if value is not None
    }  # fmt: skip
    if "hidden_fraction" in overrides:
        if command.contexts is not None:
            raise ValueError("--hidden-fraction applies to generated sets, not to --contexts")
        overrides["hidden_neurons"] = 0
    extensions = replace(extensions, **overrides)
    if command.contexts is not None:
        context_set = ContextSet.load(command.contexts)
        where = str(command.contexts)
    else:
        n_neurons = kwargs.get("n_neurons") or 8
        train_set, test_set, validation_set = make_splits(
            100, 100, n_neurons, seed=0, extensions=extensions, n_val=100
        )
        context_set = {"train": train_set, "test": test_set,
                       "validation": validation_set}[command.split]  # fmt: skip
        where = f"the generated {command.split} set ({n_neurons} neurons, seed 0)"
    policy = IdentifyAndPlan(width=command.identify_width,
                             noise_mV=extensions.observation_noise_mV)  # fmt: skip
    results = run_baselines(context_set, extensions=extensions,
                            random_seeds=command.random_seeds,
                            oracle_width=command.oracle_width, policy=policy)  # fmt: skip
    changed = ", ".join(f"{key}={value}" for key, value in overrides.items()
                        if key != "hidden_neurons")  # fmt: skip
    print(f"{len(context_set)} contexts: {where}; environment {command.env}"
          + (f" with {changed}" if changed else ""))  # fmt: skip
    print(results.table())
    print(f"wrote {results.write_csv(command.out)}")


COMMANDS = {
    "train": (train, TrainCommand),
    "evaluate": (evaluate, EvaluateCommand),
    "sweep": (sweep, SweepCommand),
    "plot": (plot, PlotCommand),
    "demo": (demo, DemoConfig),
    "contexts": (contexts, ContextsConfig),
    "baselines": (baselines, BaselinesCommand),
}


TRAIN_HELP = """Train an agent: spikectl train [PRESET] [FLAGS]. The defaults shown are
the {name} preset's: {help}

The preset (paper, quick or smoke; quick when none is given) sets every default, and
the flags override them: `spikectl train paper --help` shows the paper's. --env picks
a registered environment (spikectl/NeuronControlNoisy-v0, ...) whose settings become
the defaults of --n-neurons, --params.* and --extensions.*."""


def _train_presets(env_id: str | None = None) -> Any:
    """The presets as tyro subcommands, each with its settings as defaults (on the
    registered environment ``env_id`` when given)."""
    choices = []
    for name, experiment in PRESETS.items():
        if env_id is not None:
            experiment = dataclasses.replace(experiment, env=experiment.env.with_variant(env_id))
        default = TrainCommand(config=experiment, preset=name)
        description = TRAIN_HELP.format(name=name, help=PRESET_HELP[name])
        choices.append(
            Annotated[TrainCommand, tyro.conf.subcommand(name, default=default,
                                                         description=description)]
        )  # fmt: skip
    return Union[tuple(choices)]  # noqa: UP007


def _parse_train(argv: list[str]) -> TrainCommand:
    """The presets are tyro subcommands; without one, ``quick``. A registered --env
    other than the default changes the defaults, so the presets are built on that
    environment before the flags are parsed: every flag given still overrides the
    variant's settings (and a config never holds a variant id with the base settings)."""
    if "--preset" in argv or any(arg.startswith("--preset=") for arg in argv):
        raise ValueError(
            "--preset: the preset is a subcommand now: spikectl train paper|quick|smoke [FLAGS]"
        )
    if not argv or argv[0] not in PRESETS:
        argv = ["quick", *argv]
    kwargs = {"args": argv, "prog": "spikectl train", "command": "train"}
    env_id = _env_flag(argv)
    return _cli(_train_presets(env_id), default=_quick(env_id), **kwargs)


def _env_flag(argv: list[str]) -> str | None:
    """The value of ``--env ID`` / ``--env=ID`` (the last one given), or None."""
    env_id = None
    for index, arg in enumerate(argv):
        if arg == "--env" and index + 1 < len(argv):
            env_id = argv[index + 1]
        elif arg.startswith("--env="):
            env_id = arg.split("=", 1)[1]
    return env_id


def _quick(env_id: str | None = None) -> TrainCommand:
    experiment = PRESETS["quick"]
    if env_id is not None:
        experiment = dataclasses.replace(experiment, env=experiment.env.with_variant(env_id))
    return TrainCommand(config=experiment, preset="quick")


def _cli(*args: Any, command: str | None = None, **kwargs: Any) -> Any:
    """``tyro.cli``, with its framed parse errors turned into our one-line form."""
    captured = io.StringIO()
    reported = False
    try:
        with contextlib.redirect_stderr(captured):
            return tyro.cli(*args, **kwargs)
    except SystemExit as exit:
        line = parse_error_line(captured.getvalue()) if exit.code not in (0, None) else None
        if line is None:
            raise
        print(f"spikectl: error: {flag_message(line, command)}", file=sys.stderr)
        reported = True
        raise SystemExit(2) from None
    finally:
        if not reported:
            sys.stderr.write(captured.getvalue())  # warnings, and frames we cannot read


_BOX_TOP = re.compile(r"^╭─ (?P<title>.+?) ─+╮$")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _is_rule(line: str) -> bool:
    return bool(line) and set(line) <= {"─", "-"}


def parse_error_line(text: str) -> str | None:
    """One line from tyro's framed parse error (title, message up to the first rule,
    the help command of its footer); None when ``text`` holds no such frame.

    tyro draws the frame in box characters on UTF-8 consoles and as a title over a
    dashed rule elsewhere; both are read.
    """
    lines = [_ANSI.sub("", line).strip().strip("│╰╯").strip() for line in text.splitlines()]
    lines = [line for line in lines if line]
    top = next((i for i, line in enumerate(lines) if _BOX_TOP.match(line)), None)
    if top is not None:
        title, body = _BOX_TOP.match(lines[top]).group("title"), lines[top + 1 :]
    elif len(lines) >= 3 and not _is_rule(lines[0]) and _is_rule(lines[1]):
        title, body = lines[0], lines[2:]
    else:
        return None
    rule = next((i for i, line in enumerate(body) if _is_rule(line)), len(body))
    message = " ".join(" ".join(body[:rule]).split())
    if not message:
        return None
    # "Error parsing --seed: ..." names a flag; "Error parsing config.sizes: ..." a
    # nested config whose own message names the field (flag_message turns it into a flag).
    message = re.sub(
        r"^Error parsing (\S+):\s*",
        lambda match: f"{match.group(1)}: " if match.group(1).startswith("-") else "",
        message,
    )
    first_words = message.lower().split()[:3]
    if title != "Value error" and title.split()[0].lower() not in first_words:
        message = f"{title.lower()}: {message}"  # e.g. "missing subcommand: Expected one of"
    hint = re.search(r"(spikectl[\w .-]* --help)", " ".join(" ".join(body[rule:]).split()))
    return message + (f" (see {hint.group(1)})" if hint else "")


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``spikectl`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if argv and argv[0] == "train":
            command = _parse_train(argv[1:])
        else:
            choices = tuple(
                Annotated[config_type, tyro.conf.subcommand(name, description=run.__doc__)]
                for name, (run, config_type) in COMMANDS.items()
            )
            command = _cli(Union[choices], args=argv, prog="spikectl")  # noqa: UP007
        run = next(
            run for run, config_type in COMMANDS.values() if isinstance(command, config_type)
        )
        run(command)
    except USER_ERRORS as error:
        command = argv[0] if argv else None
        print(f"spikectl: error: {flag_message(str(error), command)}", file=sys.stderr)
        raise SystemExit(2) from error


def _flag_names(command: str | None = None) -> dict[str, str]:
    """Field names of the commands' configs (as validation messages name them) and their
    command-line flags; for ``train``, the model's and the extensions' fields are the
    --params.* and --extensions.* flags."""
    names = {}
    for config_type in (EnvConfig, AgentConfig, TrainConfig, DQNConfig,
                        *(config for _, config in COMMANDS.values())):  # fmt: skip
        for field in dataclasses.fields(config_type):
            names[field.name] = "--" + field.name.replace("_", "-")
    names["id"] = names["env"] = "--env"
    nested = [("sizes", AgentSizes)]
    if command == "train":
        nested += [("params", NeuronParams), ("extensions", Extensions)]
    for prefix, kind in nested:
        for field in dataclasses.fields(kind):
            flag = f"--{prefix}." + field.name.replace("_", "-")
            names[f"{kind.__name__}.{field.name}"] = names[f"{prefix}.{field.name}"] = flag
            if prefix != "sizes":
                names[field.name] = flag
    return names


def flag_message(message: str, command: str | None = None) -> str:
    """The message on one line, with a leading field name replaced by its flag
    (``gamma must lie in [0, 1]`` -> ``--gamma must lie in [0, 1]``) in ``command``."""
    message = " ".join(message.split())
    names = _flag_names(command)
    match = re.match(r"(NeuronParams\.|Extensions\.)?([A-Za-z_][\w.]*)", message)
    if match:
        flag = names.get((match.group(1) or "") + match.group(2)) or names.get(match.group(2))
        if flag is not None:
            message = flag + message[match.end() :]
    return message


if __name__ == "__main__":
    main()
