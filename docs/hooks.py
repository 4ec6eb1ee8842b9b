"""MkDocs hook: the command-line reference is ``spikectl CMD --help`` as the installed
code prints it, so the page cannot drift from the flags.

A page line ``<!-- spikectl-help: CMD -->`` becomes that command's help text in a code
block (``<!-- spikectl-help: -->``, no command, is the top-level help).
"""

from __future__ import annotations

import contextlib
import io
import os
import re

MARKER = re.compile(r"^<!-- spikectl-help:\s*(\S*)\s*-->$", flags=re.MULTILINE)
WIDTH = "100"  # columns tyro wraps the help to


def help_text(command: str) -> str:
    """What ``spikectl COMMAND --help`` prints (the top-level help for "")."""
    from spikectl.cli import main

    argv = [command, "--help"] if command else ["--help"]
    buffer = io.StringIO()
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH
    try:
        with contextlib.redirect_stdout(buffer), contextlib.suppress(SystemExit):
            main(argv)
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous
    lines = [line.rstrip() for line in buffer.getvalue().splitlines()]
    return "\n".join(lines).strip("\n")


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Replace each marker with its command's help."""
    return MARKER.sub(lambda match: f"```text\n{help_text(match.group(1))}\n```", markdown)
