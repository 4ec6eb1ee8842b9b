"""The lab's test tier: every test under lab/ is marked ``lab`` (``pytest -m lab lab``,
lab/README.md). The default tier (``pytest``, testpaths = tests) never collects them.

``lab/__init__.py`` makes this conftest part of the package ``lab``, so pytest puts the
repository root on ``sys.path`` before collecting, and ``import lab.planners`` works with
the ``pytest`` script as well as ``python -m pytest``."""

from __future__ import annotations

from pathlib import Path

import pytest

LAB = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if Path(item.path).resolve().is_relative_to(LAB):
            item.add_marker(pytest.mark.lab)
