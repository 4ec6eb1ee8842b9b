"""The core and the lab (lab/README.md): the lab imports the core's public API only and
reads no private (``_name``) attribute it does not define, and the core never imports the
lab. All three are read from the source, not run.

The public API, concretely: what the API reference documents. A name is public when

- a package's ``__init__`` lists it in ``__all__`` (``spikectl``, ``spikectl.planning``,
  ...: docs/reference/api/index.md says each package exports its own names), or
- a ``::: MODULE`` directive of docs/reference/api/*.md documents it: named in the
  directive's ``members:`` list, or, where the directive lists none (and does not say
  ``members: false``), a name of the module without a leading underscore (its
  ``__all__`` where it has one), or
- a ``::: MODULE.NAME`` directive documents it alone.

A module is public when a directive documents it or its package exports it; importing it
(``from spikectl.experiments import suite``) is then allowed, and so are the public names
read from it.
"""

from __future__ import annotations

import ast
import re
import sys
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
API_PAGES = ROOT / "docs" / "reference" / "api"
DIRECTIVE = re.compile(r"^::: ([\w.]+)[ \t]*\n((?:[ \t]+\S.*\n?)*)", flags=re.MULTILINE)


def module_file(dotted: str) -> Path | None:
    """The source file of a spikectl module or package, or None if there is none."""
    base = ROOT.joinpath(*dotted.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@cache
def module_names(dotted: str) -> tuple[frozenset[str] | None, frozenset[str]]:
    """(its ``__all__`` or None, the names its top level binds without a leading
    underscore: definitions, assignments and imports)."""
    path = module_file(dotted)
    if path is None:
        return None, frozenset()
    exported, bound = None, set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                if isinstance(target, ast.Name) and target.id == "__all__":
                    exported = all_of(node.value, path)
                elif isinstance(target, ast.Name):
                    bound.add(target.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
    return exported, frozenset(name for name in bound if not name.startswith("_"))


def all_of(value: ast.expr, path: Path) -> frozenset[str]:
    """``__all__``'s names: a literal list or tuple, or ``sorted(_HOMES)`` over a literal
    dict (the lazy packages, spikectl/agents/__init__.py)."""
    if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.args:
        (argument,) = value.args
        if value.func.id == "sorted" and isinstance(argument, ast.Name):
            for node in ast.parse(path.read_text()).body:
                if not isinstance(node, ast.Assign) or not isinstance(node.value, ast.Dict):
                    continue
                if argument.id in [getattr(target, "id", None) for target in node.targets]:
                    return frozenset(ast.literal_eval(key) for key in node.value.keys)
    return frozenset(ast.literal_eval(value))


@cache
def documented() -> tuple[frozenset[str], frozenset[str]]:
    """(the public modules, the public names as ``module:name``)."""
    modules, names = {"spikectl"}, set()
    for page in sorted(API_PAGES.glob("*.md")):
        for dotted, options in DIRECTIVE.findall(page.read_text()):
            if module_file(dotted) is None:  # an object: MODULE.NAME
                module, _, name = dotted.rpartition(".")
                names.add(f"{module}:{name}")
                continue
            modules.add(dotted)
            listed = re.search(r"^\s*members:[ \t]*(\S*)[ \t]*\n((?:\s*- \w+\n?)*)", options,
                               flags=re.MULTILINE)  # fmt: skip
            if listed and listed.group(1) == "false":
                continue
            if listed and listed.group(2):
                names.update(f"{dotted}:{n}" for n in re.findall(r"- (\w+)", listed.group(2)))
                continue
            exported, bound = module_names(dotted)
            names.update(f"{dotted}:{n}" for n in (exported if exported is not None else bound))
    for init in sorted((ROOT / "spikectl").rglob("__init__.py")):
        package = ".".join(init.parent.relative_to(ROOT).parts)
        exported, _ = module_names(package)
        for name in exported or ():
            names.add(f"{package}:{name}")
            if module_file(f"{package}.{name}") is not None:
                modules.add(f"{package}.{name}")
    for name in list(names):  # a documented name that is a module is a public module
        module = name.replace(":", ".")
        if module_file(module) is not None:
            modules.add(module)
    return frozenset(modules), frozenset(names)


def imports(path: Path) -> list[tuple[int, str, str | None]]:
    """(line, module, name or None) of every import in a file; a relative import is
    resolved against the file's package."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                package = path.relative_to(ROOT).parent.parts
                base = package[: len(package) - node.level + 1]
                module = ".".join([*base, module] if module else base)
            found += [(node.lineno, module, alias.name) for alias in node.names]
    return found


def shown_path(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else path.name


def non_public_imports(path: Path) -> list[str]:
    """Each import of spikectl in a file that reaches past the public API."""
    modules, names = documented()
    bad = []
    for line, module, name in imports(path):
        if module != "spikectl" and not module.startswith("spikectl."):
            continue
        if name is None:  # import spikectl.x.y
            ok = module in modules
        else:
            ok = f"{module}:{name}" in names or f"{module}.{name}" in modules
            ok = ok and (module in modules)
        if not ok:
            shown = module if name is None else f"{module}.{name}"
            bad.append(f"{shown_path(path)}:{line} imports {shown}")
    return bad


def test_the_public_api_is_read_from_the_reference():
    modules, names = documented()
    assert "spikectl:IdentifyAndPlan" in names  # the package's __all__
    assert "spikectl.experiments.stats:paired_difference_cells" in names  # no members list
    assert "spikectl.training.run:train" in names  # a members list
    assert "spikectl.training.run:train_runs" in names
    assert "spikectl.training.run:crossed_multiple" not in names  # not in that list
    assert "spikectl.training.loaders:load_controller" in names
    assert "spikectl.agents:make_agent" in names  # __all__ = sorted(_HOMES)
    assert "spikectl.experiments.suite" in modules and "spikectl.planning.beam" not in modules
    assert "spikectl.experiments:suite" not in names  # members: false, but the module is public


def test_a_non_public_import_is_named(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("from spikectl import IdentifyAndPlan\n"
                      "from spikectl.experiments import suite\n"
                      "import spikectl.experiments.stats\n"
                      "from spikectl.planning.policy import environment_settings\n"
                      "import spikectl.planning.filtering\n"
                      "from spikectl.training.run import crossed_multiple\n")  # fmt: skip
    assert non_public_imports(sample) == [
        "sample.py:4 imports spikectl.planning.policy.environment_settings",
        "sample.py:5 imports spikectl.planning.filtering",
        "sample.py:6 imports spikectl.training.run.crossed_multiple",
    ]


def test_the_lab_imports_the_public_api_only():
    lab = sorted((ROOT / "lab").rglob("*.py"))
    assert lab, "lab/ has no Python files"
    bad = [line for path in lab for line in non_public_imports(path)]
    assert not bad, f"{len(bad)} imports past the public API (tests/test_lab_boundary.py): {bad}"


def private_reads(path: Path) -> list[str]:
    """Each ``x._name`` a file reads that it does not define itself (a private attribute
    of a core class or module: ``_name`` is not the public API, whatever imported it)."""
    tree = ast.parse(path.read_text())
    defined = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            defined.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            defined.add(node.id)
    return [
        f"{shown_path(path)}:{node.lineno} reads {node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and node.attr.startswith("_")
        and not node.attr.startswith("__") and node.attr not in defined
    ]  # fmt: skip


def test_a_private_read_is_named(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("from spikectl import IdentifyAndPlan\n"
                      "class Mine(IdentifyAndPlan):\n"
                      "    def act(self, observation, info):\n"
                      "        self._seen = observation\n"
                      "        return self._seen and self._plan(info)\n")  # fmt: skip
    assert private_reads(sample) == ["sample.py:5 reads _plan"]


def test_the_lab_reads_no_private_names():
    bad = [line for path in sorted((ROOT / "lab").rglob("*.py")) for line in private_reads(path)]
    assert not bad, f"{len(bad)} reads of private names (tests/test_lab_boundary.py): {bad}"


def test_the_core_never_imports_the_lab():
    bad = [
        f"{path.relative_to(ROOT)}:{line} imports {module}"
        for path in sorted((ROOT / "spikectl").rglob("*.py"))
        for line, module, name in imports(path)
        if module == "lab" or module.startswith("lab.")
        or (module == "" and name == "lab")
    ]
    assert not bad, bad


def test_the_wheel_ships_spikectl_only():
    """pyproject's package discovery includes spikectl and its sub-packages alone, so the
    lab (a top-level package of the repository, importable from its root for the lab's own
    tests and scripts) is never installed."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pyproject admits 3.10; pytest brings tomli there (the lock pins it)
        import tomli as tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert config["packages"]["find"]["include"] == ["spikectl*"]
