"""The research record's scripts as modules: they live in folders whose names are not
Python identifiers (lab/results/realtime-iap), so a script or a test imports one by
its path."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

RESULTS = Path(__file__).resolve().parent / "results"
"""lab/results: one folder of scripts per record."""


def load_script(folder: str, name: str) -> ModuleType:
    """lab/results/FOLDER/NAME.py, imported as a module of its own (named after both)."""
    path = RESULTS / folder / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{folder.replace('-', '_')}_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
