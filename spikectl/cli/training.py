"""``spikectl train``: the presets as subcommands, the run or seed group, the results."""

from __future__ import annotations

import dataclasses
import math
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Union

import tyro

from spikectl.cli.errors import flag_for, run_tyro
from spikectl.training.config import Experiment
from spikectl.training.presets import PRESET_HELP, PRESETS


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


def flags_beside_resume(command: TrainCommand) -> list[str]:
    """The flags given with ``--resume`` that it would ignore: a setting of the tree that
    differs from the preset's, ``--run-dir``, ``--seeds``, ``--stacked``."""
    from spikectl.training.config_migration import leaf_paths

    others = (("--run-dir", command.run_dir), ("--seeds", command.seeds),
              ("--stacked", command.stacked or None))  # fmt: skip
    given = [flag for flag, value in others if value is not None]
    preset = leaf_paths(PRESETS[command.preset].to_dict())
    for path, value in leaf_paths(command.config.to_dict()).items():
        if preset.get(path) != value:
            given.append(flag_for(("config", *path), TrainCommand) or ".".join(path))
    return given


def check_given_sizes(command: TrainCommand) -> None:
    """Refuse --n-train / --n-test given (not the preset's) beside a context file of
    another size: a run records its file's size, so the number would be dropped."""
    from spikectl.contexts import ContextSet

    env, preset = command.config.env, PRESETS[command.preset].env
    for size_field, file_field in (("n_train", "train_contexts"), ("n_test", "test_contexts")):
        given, path = getattr(env, size_field), getattr(env, file_field)
        if path is None or given == getattr(preset, size_field):
            continue
        size = len(ContextSet.load(path))
        if size != given:
            flag = flag_for(("config", "env", size_field), TrainCommand)
            file_flag = flag_for(("config", "env", file_field), TrainCommand)
            raise ValueError(
                f"{flag} {given}, but {file_flag} {path} holds {size} contexts: drop {flag} "
                f"(a run records its file's size) or give {flag} {size}"
            )


def train(command: TrainCommand) -> None:
    """Train (or resume) one run or a seed group, then print the returns against the
    baselines (for a group, each seed's)."""
    from spikectl.training.group import GROUP_FILE, group_configs, group_is_stacked, seed_dirs
    from spikectl.training.run import train_runs
    from spikectl.training.run_files import check_run_path, read_config

    resume, stacked = command.resume is not None, command.stacked
    if resume:
        given = flags_beside_resume(command)
        if given:
            raise ValueError(
                f"--resume continues the run exactly as it was saved (its config.json); it "
                f"takes no other settings, got {', '.join(given)}: drop them, or start a new "
                "run in another --run-dir"
            )
    if not resume:
        check_given_sizes(command)
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
    if not resume:  # before the directory is named: a name that cannot be printed
        check_run_path(group_dir or run_dirs[0])
    if group_dir is None:
        print(f"run directory: {run_dirs[0]}")
    else:
        how = "stacked" if stacked else "in one process"
        print(f"seed group: {group_dir} ({len(configs)} seeds {how})")
    with warnings.catch_warnings():
        # A run's warnings (a best_model.pt set aside, another kind of CPU) are one line
        # each, printed when they happen.
        warnings.simplefilter("always", RuntimeWarning)
        warnings.showwarning = _one_line_warning(warnings.showwarning)
        metrics = train_runs(configs, run_dirs, group_dir, resume=resume, stacked=stacked)
    if group_dir is None:
        _print_run(configs[0], run_dirs[0], metrics[0])
    else:
        _print_group(configs, run_dirs, metrics)


def _one_line_warning(show):
    """``warnings.showwarning`` printing RuntimeWarnings as ``spikectl: warning: ...``."""

    def one_line(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, RuntimeWarning):
            return show(message, category, filename, lineno, file, line)
        print(f"spikectl: warning: {message}", file=sys.stderr, flush=True)

    return one_line


def _holds_best(run_dir: Path, episode: int) -> bool:
    """Whether run_dir/best_model.pt is the network of that episode (the table names it)."""
    from spikectl.training.run_files import BEST_MODEL_FILE, RunDirError
    from spikectl.training.torch_files import model_episode

    try:
        return model_episode(run_dir / BEST_MODEL_FILE) == episode
    except (RunDirError, OSError):
        return False


def _core_minutes(final: dict) -> str:
    """The last metrics row's core-minutes, and the part spent evaluating where the run
    measured it (NaN in runs resumed from checkpoints before that clock)."""
    evaluating = final.get("eval_cpu_time_s", math.nan) / 60
    of_which = "" if math.isnan(evaluating) else f", {evaluating:.1f} of them evaluating"
    return f"{final['cpu_time_s'] / 60:.1f} core minutes{of_which}"


SHOWN_RUN_FILES = (
    "model.pt", "best_model.pt", "checkpoint.pt", "metrics.csv", "learning_curve.png",
    "baselines.json", "config.json", "machine.json", "train_contexts.npz", "test_contexts.npz",
    "val_contexts.npz", "tensorboard",
)  # fmt: skip
"""What a run directory holds at the end of a run, in the order the last line names it."""


def written_files(run_dir: Path, curve: Path) -> str:
    """The files of a finished run (``curve`` among them), the ones read most first."""
    present = {path.name for path in run_dir.iterdir()}
    shown = [name for name in SHOWN_RUN_FILES if name in present]
    if curve.parent != run_dir:  # drawn elsewhere: named in full
        shown.append(str(curve))
    return ", ".join(shown)


def _print_run(config: Experiment, run_dir: Path, metrics: list[dict]) -> None:
    """A single run's final returns, its baselines and its best network on validation."""
    from spikectl.experiments.figures import plot_learning_curve
    from spikectl.files import read_json_file
    from spikectl.training.run import best_on_validation

    final = metrics[-1]
    baselines = read_json_file(run_dir / "baselines.json")
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
            f"{'best_model.pt' if _holds_best(run_dir, best['episode']) else 'not kept'})"
        )
    print(
        f"{final['env_steps']:,} environment steps, {final['updates']:,} updates, "
        f"{final['wall_time_s'] / 60:.1f} wall minutes ({_core_minutes(final)}) on "
        f"{config.train.torch_threads or torch_threads()} thread(s)"
    )
    print(f"wrote in {run_dir}: {written_files(run_dir, curve)}")


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
        f"({_core_minutes(final)}) for the whole group"
    )
    names = {path.name for run_dir in run_dirs for path in run_dir.iterdir()}
    listed = ", ".join(name for name in SHOWN_RUN_FILES if name in names)
    print(f"wrote in each of {', '.join(str(d) for d in run_dirs)}: {listed}")


TRAIN_HELP = """Train an agent: spikectl train [PRESET] [FLAGS]. The defaults shown are
the {name} preset's: {help}

The preset ({presets}; quick when none is given) sets every default, and
the flags override them: `spikectl train paper --help` shows the paper's. --env picks
a registered environment (spikectl/NeuronControlNoisy-v0, ...) whose settings become
the defaults of --n-neurons, --params.* and --extensions.*. --task T trains on task T of
the benchmark suite (docs/benchmark.md; v1, or --suite 2 for the rig's loop): its
environment, n and extensions, whose default context sets are the task's training and
validation sets."""


def _train_presets(env_id: str | None = None) -> Any:
    """The presets as tyro subcommands, each with its settings as defaults (on the
    registered environment ``env_id`` when given)."""
    choices = []
    for name, experiment in PRESETS.items():
        if env_id is not None:
            experiment = dataclasses.replace(experiment, env=experiment.env.with_variant(env_id))
        default = TrainCommand(config=experiment, preset=name)
        description = TRAIN_HELP.format(
            name=name, help=PRESET_HELP[name], presets=", ".join(PRESETS)
        )
        choices.append(
            Annotated[TrainCommand, tyro.conf.subcommand(name, default=default,
                                                         description=description)]
        )  # fmt: skip
    return Union[tuple(choices)]  # noqa: UP007


def parse_train(argv: list[str], command_types: tuple[type, ...] = ()) -> TrainCommand:
    """The presets are tyro subcommands; without one, ``quick``. A registered --env
    other than the default changes the defaults, so the presets are built on that
    environment before the flags are parsed: every flag given still overrides the
    variant's settings (and a config never holds a variant id with the base settings).
    ``command_types`` name the flags in tyro's parse errors."""
    if "--preset" in argv or any(arg.startswith("--preset=") for arg in argv):
        raise ValueError(
            f"--preset: the preset is a subcommand now: spikectl train {'|'.join(PRESETS)} [FLAGS]"
        )
    if not argv or argv[0] not in PRESETS:
        argv = ["quick", *argv]
    argv = _expand_task_flag(argv)
    kwargs = {"args": argv, "prog": "spikectl train", "command_types": command_types}
    env_id = _env_flag(argv)
    return run_tyro(_train_presets(env_id), default=_quick(env_id), **kwargs)


def _expand_task_flag(argv: list[str]) -> list[str]:
    """``--task T`` / ``--task=T`` (of suite version ``--suite N``, 1 when not given)
    replaced by the suite task's own flags (--env, --n-neurons, --extensions.*, its set
    sizes and seed), placed right after the preset so that every flag given on the
    command line still overrides them. One task at most, and not beside a context file
    (the task's sets are its own)."""
    given: dict[str, list[str]] = {"--task": [], "--suite": []}
    rest, index = [argv[0]], 1
    while index < len(argv):
        arg = argv[index]
        flag = arg.split("=", 1)[0]
        if flag not in given:
            rest.append(arg)
        elif "=" in arg:
            given[flag].append(arg.split("=", 1)[1])
        elif index + 1 >= len(argv) or argv[index + 1].startswith("--"):
            raise ValueError(
                "--task: give a task of the benchmark suite, e.g. --task noise2, "
                "--task latency1 --suite 2"
                if flag == "--task"
                else "--suite: give a suite version, e.g. --suite 2"
            )
        else:
            given[flag].append(argv[index + 1])
            index += 1
        index += 1
    tasks, versions = given["--task"], given["--suite"]
    if versions and not tasks:
        raise ValueError("--suite: give it with --task (the suite version the task is from)")
    if len(versions) > 1:
        raise ValueError(f"--suite: one version per run, got {', '.join(versions)}")
    if not tasks:
        return argv
    if len(tasks) > 1:
        raise ValueError(f"--task: one task per run, got {', '.join(tasks)}")
    for flag in ("--train-contexts", "--test-contexts", "--resume"):
        if flag == "--resume" and any(arg == flag or arg.startswith(flag + "=") for arg in rest):
            raise ValueError(
                f"--task {tasks[0]} starts a run on the task's sets; --resume continues a run "
                "with its own recorded settings: give one of them"
            )
        if any(arg == flag or arg.startswith(flag + "=") for arg in rest):
            raise ValueError(
                f"--task {tasks[0]} trains on the task's pinned sets, {flag} on a file of "
                f"its own: give one of them"
            )
    from spikectl.experiments import suite

    try:
        version = int(versions[0]) if versions else suite.DEFAULT_SUITE
    except ValueError:
        raise ValueError(f"--suite: a suite version number (1, 2), got {versions[0]!r}") from None
    try:
        return [rest[0], *suite.train_arguments(tasks[0], version), *rest[1:]]
    except ValueError as error:
        raise ValueError(f"--task: {error}") from None


def _env_flag(argv: list[str]) -> str | None:
    """The value of ``--env ID`` / ``--env=ID`` (the last one given), or None; the flag
    is env.id's in the command's flag table."""
    flag, env_id = flag_for(("config", "env", "id"), TrainCommand), None
    for index, arg in enumerate(argv):
        if arg == flag and index + 1 < len(argv):
            env_id = argv[index + 1]
        elif arg.startswith(f"{flag}="):
            env_id = arg.split("=", 1)[1]
    return env_id


def _quick(env_id: str | None = None) -> TrainCommand:
    experiment = PRESETS["quick"]
    if env_id is not None:
        experiment = dataclasses.replace(experiment, env=experiment.env.with_variant(env_id))
    return TrainCommand(config=experiment, preset="quick")
