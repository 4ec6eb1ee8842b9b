"""MkDocs hooks.

- The command-line reference is ``spikectl CMD --help`` as the installed code prints it,
  so the page cannot drift from the flags: a page line ``<!-- spikectl-help: CMD -->``
  becomes that command's help text in a code block (``<!-- spikectl-help: -->``, no
  command, is the top-level help).
- Headings get GitHub's anchors (``github_slug``), so that one link works on the
  repository and on the site, whatever version of Markdown or pymdown-extensions is
  installed (their slug functions have changed between releases). tests/test_docs.py
  checks every link's anchor with the same function.
"""

from __future__ import annotations

import contextlib
import io
import os
import re

MARKER = re.compile(r"^<!-- spikectl-help:\s*(\S*)\s*-->$", flags=re.MULTILINE)
WIDTH = "100"  # columns tyro wraps the help to
# GitHub keeps letters, digits, marks, "_", "-" and spaces, and drops everything else.
NOT_IN_A_SLUG = re.compile(r"[^\w\- ]")


def github_slug(text: str, separator: str = "-") -> str:
    """The anchor GitHub gives a heading whose text is ``text`` (as rendered: no markup).

    Lower case, every character but word characters, hyphens and spaces dropped, each
    space one hyphen (never collapsed: ``"a = b"`` is ``a--b``). ``separator`` is
    Python-Markdown's argument; GitHub's is always a hyphen, and so is this one's.
    """
    del separator
    return NOT_IN_A_SLUG.sub("", text.strip().lower()).replace(" ", "-")


def on_config(config):
    """Give every heading GitHub's anchor (the toc extension's slug function)."""
    config["mdx_configs"].setdefault("toc", {})["slugify"] = github_slug
    return config


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
