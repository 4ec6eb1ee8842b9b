"""Fixtures shared by several test modules (no test module imports another)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import torch


def _comparable(rows: list[dict]) -> list[dict]:
    clocks = ("wall_time_s", "cpu_time_s")
    return [{k: None if v != v else v for k, v in row.items() if k not in clocks} for row in rows]


def _assert_same_weights(path_a: Path, path_b: Path) -> None:
    a = torch.load(path_a, weights_only=True)
    b = torch.load(path_b, weights_only=True)
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


@pytest.fixture
def comparable() -> Callable[[list[dict]], list[dict]]:
    """Metrics rows without the clocks, which no two runs share (NaN made comparable)."""
    return _comparable


@pytest.fixture
def assert_same_weights() -> Callable[[Path, Path], None]:
    """Assert that two saved state dicts (model.pt) hold bit-identical tensors."""
    return _assert_same_weights
