"""What the command line says when it refuses: one line, ``spikectl: error: ...``, exit 2.

- A :class:`ConfigError` names its field by path. Its path within the command's config
  is the path of the config object that raised it (the innermost one on its traceback)
  followed by the error's own path; :func:`flag_for` looks that path up in a table of the
  command's flags built with tyro's naming (:func:`field_flags`). The message is never read.
- tyro's own parse errors (a bad literal, a missing subcommand) come as framed text;
  :func:`parse_error_line` reads one line out of the frame. This is what remains of
  reading tyro's printed output, and why: tyro (1.0.17 checked) has no public API that
  hands parse errors over as data. Its one way, ``tyro._errors.on_parse_error`` (events
  such as ``MissingSubcommand``, ``InvalidChoice``, ``UnrecognizedArgs``,
  ``InstantiationFailure``), is private by its own docstring ("may change or be removed
  in any release ... pin an exact tyro version"), serves the default backend only and
  is not promised by the older tyro releases that ``tyro>=0.8`` admits. Once tyro makes it
  public, :func:`run_tyro` can take the events and the frame reader can go. A
  config's own refusal needs no reading: it is the ConfigError itself
  (:func:`config_error_in`), named by field path, never by its message.
- Any other user error (a plain ``ValueError`` from outside the configs, such as
  ``make_splits``' argument checks) keeps the older reading: a leading field name in its
  message becomes its flag (:func:`flag_message`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import io
import re
import sys
import traceback
from collections.abc import Iterable, Iterator
from types import UnionType
from typing import Annotated, Any, Union, get_args, get_origin, get_type_hints

import tyro

from spikectl.config_errors import ConfigError, MissingExtraError
from spikectl.experiments.sweep import SweepError
from spikectl.files import FileWriteError
from spikectl.training.run_files import RunDirError

USER_ERRORS = (
    ValueError, FileNotFoundError, FileWriteError, RunDirError, SweepError, MissingExtraError,
)  # fmt: skip
"""What the commands raise for bad input or a bad file system: reported in one line with
exit status 2. ValueError covers every validation error of the library (ConfigError,
ContextFileError, TooLargeError, argument checks); anything else is a bug and keeps its
traceback."""

_ARG_CONFIG = type(tyro.conf.arg())
FieldPath = tuple[str, ...]


def _walk(
    kind: type, path: FieldPath = (), names: FieldPath = ()
) -> Iterator[tuple[FieldPath, FieldPath, Any]]:
    """(path, flag name parts, type) of every field of the dataclass ``kind`` and of the
    dataclasses nested in it. tyro names a flag by the fields' names joined by dots; a
    field marked ``tyro.conf.arg(name=N)`` goes by N, and by none when N is ``""`` (its
    fields sit at the level above); a suppressed field has no flag."""
    hints = get_type_hints(kind, include_extras=True)
    for field in dataclasses.fields(kind):
        hint, name = hints[field.name], field.name
        extras: tuple[Any, ...] = ()
        if get_origin(hint) is Annotated:
            hint, *extras = get_args(hint)
        if tyro.conf.Suppress in extras:
            continue
        for extra in extras:
            if isinstance(extra, _ARG_CONFIG) and extra.name is not None:
                name = extra.name
        here, flag = (*path, field.name), (*names, name) if name else names
        # A union of configs (the learner's) collapses to the preset's member on the
        # command line, with that member's flags at the same place: walk every member.
        members = get_args(hint) if get_origin(hint) in (Union, UnionType) else (hint,)
        for member in members:
            yield here, flag, member
            if dataclasses.is_dataclass(member):
                yield from _walk(member, here, flag)


@functools.cache
def field_flags(kind: type) -> dict[FieldPath, str]:
    """The flag of each field of the command config ``kind``, by the field's path:
    for ``TrainCommand``, ``("config", "learner", "gamma")`` -> ``--gamma``,
    ``("config", "env", "id")`` -> ``--env``, ``("config", "env", "params", "dt_ms")``
    -> ``--params.dt-ms``."""
    return {
        path: "--" + ".".join(names).replace("_", "-")
        for path, names, hint in _walk(kind)
        if not dataclasses.is_dataclass(hint)
    }


@functools.cache
def config_places(kind: type) -> dict[type, FieldPath]:
    """Where each config class nested in the command config ``kind`` sits in it."""
    places: dict[type, FieldPath] = {kind: ()}
    for path, _, hint in _walk(kind):
        if dataclasses.is_dataclass(hint):
            places.setdefault(hint, path)
    return places


def flag_for(path: Iterable[str], command: type) -> str | None:
    """The flag of the field at ``path`` in the command config class ``command``
    (``TrainCommand``, ``DemoConfig``, ...), or None when no flag sets it."""
    return field_flags(command).get(tuple(path))


def command_path(error: ConfigError, command: type) -> FieldPath:
    """``error``'s field within ``command``: the place of the config that raised it (the
    innermost config of ``command``'s tree on its traceback, as ``self`` of its own
    checks or as the ``config`` a function was handed: tyro builds the tree from the
    inside out, so an ``EnvConfig`` refuses ``("n_train",)`` before any ``Experiment``
    holds it, and a run refuses ``("agent", "init_from")`` of its Experiment), then the
    error's own path."""
    places, place = config_places(command), ()
    for frame, _ in traceback.walk_tb(error.__traceback__):
        for owner in (frame.f_locals.get("self"), frame.f_locals.get("config")):
            if type(owner) in places:
                place = places[type(owner)]
                break
    return (*place, *error.path)


def config_error_line(error: ConfigError, command: type | None) -> str:
    """The error's message with its field named by the command's flag, where one sets it
    (else the message as it is)."""
    flag = None if command is None else flag_for(command_path(error, command), command)
    return " ".join((str(error) if flag is None else error.naming(flag)).split())


def config_error_in(exit: BaseException) -> ConfigError | None:
    """The ConfigError behind a tyro parse failure (tyro wraps what a nested config
    raises in its own error and exits), or None."""
    seen, cause = set(), exit.__context__
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, ConfigError):
            return cause
        seen.add(id(cause))
        cause = cause.__context__
    return None


def run_tyro(*args: Any, command_types: Iterable[type] = (), **kwargs: Any) -> Any:
    """``tyro.cli``, with its framed parse errors turned into our one-line form (the
    flags named from ``command_types``) and a config's refusal raised as the ConfigError
    itself."""
    captured = io.StringIO()
    reported, refused = False, None
    argv = list(kwargs.get("args") or ())
    # The subcommand chosen (a preset, a command): tyro suggests the flags of all of them.
    chosen = argv[0] if argv and argv[0] in _subcommand_names(args[0] if args else None) else None
    try:
        with contextlib.redirect_stderr(captured):
            return tyro.cli(*args, **kwargs)
    except SystemExit as exit:
        if exit.code in (0, None):
            raise
        refused = config_error_in(exit)
        line = (
            None
            if refused is not None
            else parse_error_line(captured.getvalue(), chosen, kwargs.get("prog"))
        )
        if refused is None and line is None:
            raise
        reported = True
        if refused is None:
            print(f"spikectl: error: {flag_message(line, command_types)}", file=sys.stderr)
            raise SystemExit(2) from None
    finally:
        if not reported:
            sys.stderr.write(captured.getvalue())  # warnings, and frames we cannot read
    raise refused


def _subcommand_names(kind: Any) -> set[str]:
    """The names of the subcommands of a union of ``tyro.conf.subcommand`` types."""
    names = set()
    for member in get_args(kind) if get_origin(kind) in (Union, UnionType) else ():
        for extra in get_args(member)[1:] if get_origin(member) is Annotated else ():
            name = getattr(extra, "name", None)
            if isinstance(name, str) and type(extra).__name__ == "_SubcommandConfig":
                names.add(name)
    return names


_BOX_TOP = re.compile(r"^╭─ (?P<title>.+?) ─+╮$")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _is_rule(line: str) -> bool:
    return bool(line) and set(line) <= {"─", "-"}


def parse_error_line(text: str, chosen: str | None = None, prog: str | None = None) -> str | None:
    """One line from tyro's framed parse error (title, message up to the first rule,
    the flags it suggests, the help command of its footer); None when ``text`` holds no
    such frame.

    tyro draws the frame in box characters on UTF-8 consoles and as a title over a
    dashed rule elsewhere; both are read. For a misspelt flag tyro suggests the near
    flags of every subcommand, each followed by the help commands of the subcommands
    that have it: only those of ``chosen`` (the subcommand given) are named, and the
    help command is ``PROG CHOSEN --help``.
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
    # nested config whose own message names the field.
    message = re.sub(
        r"^Error parsing (\S+):\s*",
        lambda match: f"{match.group(1)}: " if match.group(1).startswith("-") else "",
        message,
    )
    first_words = message.lower().split()[:3]
    if title != "Value error" and title.split()[0].lower() not in first_words:
        message = f"{title.lower()}: {message}"  # e.g. "missing subcommand: Expected one of"
    rest = body[rule:]
    flags = _suggested_flags(rest, chosen)
    if chosen is not None and prog:
        hint = f"{prog} {chosen} --help"
    else:
        commands = (re.sub(r"^.*?\b(?:run|see) ", "", line) for line in rest)
        found = (re.fullmatch(r"(\S+(?: [\w.-]+)*? --help)", line) for line in commands)
        hint = next((match.group(1) for match in found if match), None)
    said = []
    if flags:
        said.append(f"did you mean {' or '.join(flags)}?")
    if hint:
        said.append(f"see {hint}")
    return message + (f" ({' '.join(said)})" if said else "")


_SUGGESTED = re.compile(r"^(--[\w.-]+)(?:\s|$)")
_IN_HELP = re.compile(r"^in (\S+(?: \S+)*) --help$")


def _suggested_flags(lines: list[str], chosen: str | None, most: int = 3) -> list[str]:
    """The flags under tyro's "Perhaps you meant:" that ``chosen`` has (each flag's
    entry ends with "in PROG SUBCOMMAND --help" lines; without them, every flag)."""
    where: dict[str, list[str]] = {}
    flag, suggesting = None, False
    for line in lines:
        if _is_rule(line) or line.endswith(":"):
            suggesting = line == "Perhaps you meant:"
        elif not suggesting:
            continue
        elif match := _SUGGESTED.match(line):
            flag = match.group(1)
            where.setdefault(flag, [])
        elif flag is not None and (match := _IN_HELP.match(line)):
            where[flag].append(match.group(1).split()[-1])
    return [
        flag for flag, places in where.items()
        if chosen is None or not places or chosen in places
    ][:most]  # fmt: skip


def flag_message(message: str, command_types: Iterable[type] = ()) -> str:
    """For errors that are not ConfigErrors: the message on one line, a leading field
    name replaced by its flag (``n_test must be ...`` -> ``--n-test must be ...``), the
    names being the top-level flags of ``command_types``."""
    message = " ".join(message.split())
    names = {}
    for kind in command_types:
        for path, flag in field_flags(kind).items():
            if "." not in flag:
                names[path[-1]] = flag
    # A field name, not the start of a file name ("test_contexts.npz: ..." is a file).
    match = re.match(r"[A-Za-z_]\w*(?![\w./\\-])", message)
    if match and match.group() in names:
        message = names[match.group()] + message[match.end() :]
    return message
