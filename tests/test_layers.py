"""The package's layers: imports run downward only, with no cycles.

neuron model -> contexts -> environments -> agents (learned or planned) -> training ->
bridges -> experiments -> CLI. Read statically from the source, lazy (function-level) imports
included, so a layer cannot reach upward even where the import would run late.
"""

from __future__ import annotations

import ast
import graphlib
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parent.parent / "spikectl"

LAYERS = (
    (
        "spikectl.files",
        "spikectl.config_errors",
        "spikectl.seeds",
        "spikectl.version",
        "spikectl.environment_variables",
        "spikectl.registry",
    ),
    ("spikectl.file_kinds", "spikectl.locks"),
    ("spikectl.neuron",),
    ("spikectl.contexts",),
    ("spikectl.envs",),
    ("spikectl.wrappers",),
    ("spikectl.agents", "spikectl.planning"),
    ("spikectl.training",),
    ("spikectl.bridges",),
    ("spikectl.experiments",),
    ("spikectl.cli", "spikectl"),
)
"""Lowest first. A module may import its own layer's package and the layers below it;
the packages that share a layer (agents and planning) do not import each other. The
bridges to other simulators (spikectl.bridges, each imported only with its extra) sit
above the controllers they play and below everything that might import them."""


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path for path in sorted(PACKAGE_DIR.rglob("*.py"))}


def layer_of(module: str) -> tuple[int, str]:
    """(layer index, the layer package holding ``module``): the longest matching prefix."""
    matches = [
        (len(package), index, package)
        for index, packages in enumerate(LAYERS)
        for package in packages
        if module == package or module.startswith(package + ".")
    ]
    assert matches, f"{module} is in no layer: add it to LAYERS"
    _, index, package = max(matches)
    return index, package


def imported_modules(module: str) -> set[str]:
    """The spikectl modules ``module`` imports anywhere in its source."""
    tree = ast.parse(MODULES[module].read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                submodule = f"{node.module}.{alias.name}"
                if submodule in MODULES:
                    found.add(submodule)  # `from spikectl.envs import render`
                else:
                    found.add(node.module)
    return {name for name in found if name in MODULES and name != module}


IMPORTS = {module: imported_modules(module) for module in MODULES}


def test_every_module_is_in_a_layer():
    for module in MODULES:
        layer_of(module)


def test_imports_run_downward_only():
    upward = []
    for module, imported in IMPORTS.items():
        index, package = layer_of(module)
        for target in imported:
            target_index, target_package = layer_of(target)
            if target_index > index or (target_index == index and target_package != package):
                upward.append(f"{module} imports {target}")
    assert upward == []


def test_no_import_cycles():
    # Package __init__ files import their own submodules; a submodule reaching back into
    # its own package's __init__ would close a cycle and is reported too.
    try:
        tuple(graphlib.TopologicalSorter(IMPORTS).static_order())
    except graphlib.CycleError as error:
        pytest.fail(f"import cycle: {' -> '.join(error.args[1])}")


def test_the_lower_layers_do_not_import_the_heavy_libraries():
    # Importing spikectl registers the environments and nothing else: no torch, no
    # plotting, no CLI parser.
    code = (
        "import sys, spikectl, spikectl.envs, spikectl.contexts, spikectl.neuron; "
        "print(sorted(m for m in ('torch', 'matplotlib', 'tyro') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize(
    "module", ["spikectl.neuron", "spikectl.contexts", "spikectl.envs", "spikectl.planning"]
)
def test_each_layer_package_imports_on_its_own(module):
    subprocess.run([sys.executable, "-c", f"import {module}"], check=True)
