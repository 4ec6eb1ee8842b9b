"""The ``spikectl`` command line: thin wrappers, one typed config per subcommand (tyro).

One module per concept: ``training`` (``spikectl train``: the presets as subcommands, the
run or seed group), ``context_sets`` (``demo``, ``contexts``), ``runs`` (``evaluate``,
``sweep``, ``plot``), ``baseline_policies`` (``baselines``), ``realtime`` (the 1 kHz
rig), ``benchmark`` (the frozen suite), ``errors`` (how a refusal
becomes one line naming the flag) and ``interrupts`` (how a Ctrl-C becomes one line and
exit 130). This module holds the command table and ``main``.
"""

from __future__ import annotations

import os
import sys
from typing import Annotated, Union

import tyro

from spikectl.cli.baseline_policies import BaselinesCommand, baselines
from spikectl.cli.benchmark import BenchmarkCommand, benchmark
from spikectl.cli.context_sets import ContextsConfig, DemoConfig, contexts, demo
from spikectl.cli.errors import (
    USER_ERRORS,
    config_error_line,
    flag_for,
    flag_message,
    parse_error_line,
    run_tyro,
)
from spikectl.cli.interrupts import (
    INTERRUPTED,
    TERMINATED,
    TERMINATED_EXIT_STATUS,
    caused_by_interrupt,
    ignore_interrupts_at_exit,
    interrupts_delivered,
    terminated_by,
)
from spikectl.cli.realtime import RealtimeCommand, realtime
from spikectl.cli.runs import EvaluateCommand, PlotCommand, SweepCommand, evaluate, plot, sweep
from spikectl.cli.training import TrainCommand, parse_train, train
from spikectl.config_errors import ConfigError
from spikectl.files import describe_os_error

__all__ = [
    "COMMANDS", "USER_ERRORS", "BaselinesCommand", "BenchmarkCommand", "ContextsConfig",
    "DemoConfig", "EvaluateCommand", "PlotCommand", "RealtimeCommand", "SweepCommand",
    "TrainCommand", "flag_for", "main",
    "parse_error_line",
]  # fmt: skip

COMMANDS = {
    "train": (train, TrainCommand),
    "evaluate": (evaluate, EvaluateCommand),
    "sweep": (sweep, SweepCommand),
    "plot": (plot, PlotCommand),
    "demo": (demo, DemoConfig),
    "contexts": (contexts, ContextsConfig),
    "baselines": (baselines, BaselinesCommand),
    "realtime": (realtime, RealtimeCommand),
    "benchmark": (benchmark, BenchmarkCommand),
}


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``spikectl`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    command_types = tuple(config_type for _, config_type in COMMANDS.values())
    try:
        with interrupts_delivered():
            command = _parse(argv, command_types)
            run = next(
                run for run, config_type in COMMANDS.values() if isinstance(command, config_type)
            )
            run(command)
    except ConfigError as error:
        command_type = COMMANDS[argv[0]][1] if argv and argv[0] in COMMANDS else None
        print(f"spikectl: error: {config_error_line(error, command_type)}", file=sys.stderr)
        raise SystemExit(2) from error
    except USER_ERRORS as error:
        print(f"spikectl: error: {flag_message(str(error), command_types)}", file=sys.stderr)
        raise SystemExit(2) from error
    except BrokenPipeError:
        # The reader went away (``spikectl evaluate RUN | head -1``): what it wanted it
        # has; stop quietly, as a shell tool does, without a second error at exit.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        raise SystemExit(141) from None
    except (KeyboardInterrupt, SystemError) as error:
        # Ctrl-C inside a Numba kernel comes back as a SystemError whose cause is the
        # KeyboardInterrupt; any other SystemError is a bug and keeps its traceback.
        if not caused_by_interrupt(error):
            raise
        ignore_interrupts_at_exit()
        terminated = terminated_by(error)
        if terminated is not None:  # SIGTERM: a run says what it kept
            print(f"spikectl: {terminated}" if str(terminated) else TERMINATED, file=sys.stderr)
            raise SystemExit(TERMINATED_EXIT_STATUS) from None
        print(INTERRUPTED, file=sys.stderr)
        raise SystemExit(130) from None
    except OSError as error:
        # The machine's problem, not spikectl's (a full disk under TensorBoard's writer,
        # a file system gone read-only): one line naming it.
        where = f"{error.filename}: " if error.filename else ""
        print(f"spikectl: error: {where}{describe_os_error(error)}", file=sys.stderr)
        raise SystemExit(2) from error


def _parse(argv: list[str], command_types: tuple[type, ...]) -> object:
    """The typed config of the command ``argv`` names (``train``'s presets have their own
    parser)."""
    if argv and argv[0] == "train":
        return parse_train(argv[1:], command_types)
    choices = tuple(
        Annotated[config_type, tyro.conf.subcommand(name, description=run.__doc__)]
        for name, (run, config_type) in COMMANDS.items()
    )
    return run_tyro(Union[choices], args=argv, prog="spikectl",  # noqa: UP007
                    command_types=command_types)  # fmt: skip
