"""The house rules CONTRIBUTING states, held statically: one concept per module (no module
over 400 lines) and no public function or constructor over 8 parameters; a reader who opens
any file of the core finds it readable in one sitting and any call readable in one line."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parent.parent / "spikectl"
SOURCES = sorted(PACKAGE_DIR.rglob("*.py"))

MAX_MODULE_LINES = 400
MAX_PARAMETERS = 8
"""Parameters of a public function or constructor, ``self`` and ``cls`` not counted
(``*args`` and ``**kwargs`` count as one each)."""


def parameter_count(function: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    arguments = function.args
    named = arguments.posonlyargs + arguments.args + arguments.kwonlyargs
    count = sum(argument.arg not in ("self", "cls") for argument in named)
    return count + (arguments.vararg is not None) + (arguments.kwarg is not None)


def public_functions(tree: ast.Module):
    """Functions a user may call: module-level ones and methods of module-level classes
    whose names do not start with an underscore (``__init__`` is public: the
    constructor), and not those under ``typing.overload``."""

    def is_overload(function) -> bool:
        return any(getattr(d, "id", getattr(d, "attr", None)) == "overload"
                   for d in function.decorator_list)  # fmt: skip

    def public(name: str) -> bool:
        return not name.startswith("_") or name == "__init__"

    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            if public(node.name) and not is_overload(node):
                yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for member in node.body:
                if isinstance(member, ast.FunctionDef | ast.AsyncFunctionDef):
                    if public(member.name) and not is_overload(member):
                        yield f"{node.name}.{member.name}", member


def test_the_rules_see_a_breach():
    tree = ast.parse(
        "def f(a, b, c, d, e, f, g, h, i): pass\n"
        "class C:\n    def __init__(self, a, *args, **kwargs): pass\n"
        "def _private(a, b, c, d, e, f, g, h, i): pass\n"
    )
    counts = {name: parameter_count(node) for name, node in public_functions(tree)}
    assert counts == {"f": 9, "C.__init__": 3}


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE_DIR)))
def test_no_module_over_400_lines(path):
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_MODULE_LINES, f"{path.name} has {lines} lines: split it by concept"


def test_no_public_function_over_8_parameters():
    breaches = [
        f"{path.relative_to(PACKAGE_DIR)}:{node.lineno} {name} ({parameter_count(node)})"
        for path in SOURCES
        for name, node in public_functions(ast.parse(path.read_text()))
        if parameter_count(node) > MAX_PARAMETERS
    ]
    assert breaches == []
