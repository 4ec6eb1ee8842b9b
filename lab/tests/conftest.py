"""The lab's test tier: every test here is marked ``lab`` (``pytest -m lab lab/tests``,
lab/README.md). The default tier (``pytest``, testpaths = tests) never collects them."""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    here = __file__.rsplit("/", 1)[0]
    for item in items:
        if str(item.path).startswith(here):
            item.add_marker(pytest.mark.lab)
