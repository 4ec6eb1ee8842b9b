"""Every script in examples/ runs as a user runs it (a subprocess, its --short mode) and
prints what it should."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run_example(name: str, *args: str, cwd: Path) -> str:
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True, text=True, cwd=cwd, timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def number(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match, f"{pattern!r} not in {text!r}"
    return float(match.group(1))


def test_every_example_has_a_test():
    # examples of an extra are run by that extra's tests (cleo_closed_loop.py: test_bridge_cleo)
    tests = "".join(path.read_text() for path in Path(__file__).parent.glob("test_*.py"))
    tested = set(re.findall(r'"(\w+\.py)"', tests))
    assert {path.name for path in EXAMPLES.glob("*.py")} <= tested


def test_gymnasium_loop(tmp_path):
    out = run_example("gymnasium_loop.py", "--short", cwd=tmp_path)
    assert 0.0 <= number(r"mean return ([\d.]+) over 2 episodes", out) <= 1.0
    assert "vector env: 8 networks stepped" in out


def test_your_own_connectome(tmp_path):
    out = run_example("your_own_connectome.py", "--short", cwd=tmp_path)
    assert "context 0: target n" in out and "context 1: target n" in out
    # The witness reproduces each pattern exactly: the best return, 1, on every network.
    assert "the witness scores [1.0, 1.0] on your networks" in out
    assert not (tmp_path / "my_contexts.npz").exists()  # --short writes nothing


def test_realtime_controller(tmp_path):
    out = run_example("realtime_controller.py", "--short", cwd=tmp_path)
    assert out.startswith("identify-and-plan at 100 Hz, 1 episode(s):")
    misses = number(r"misses (\d+)", out)
    assert 0 <= misses <= 60 and 0.0 <= number(r"mean_return ([\d.]+)", out) <= 1.0


def test_plot_a_run(tmp_path):
    out = run_example("plot_a_run.py", "--short", cwd=tmp_path)
    assert "tdrqn seed 0: 5 evaluations, last at 6400 steps" in out
    written = tmp_path / re.findall(r"wrote (\S+)", out)[-1]
    assert written.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_a_run_draws_the_metrics():
    spec = importlib.util.spec_from_file_location("plot_a_run", EXAMPLES / "plot_a_run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rows = [{"env_steps": 0.0, "train_return": 0.5, "test_return": 0.49},
            {"env_steps": 800.0, "train_return": 0.6, "test_return": 0.55}]  # fmt: skip
    figure = module.draw(rows, {"do_nothing": {"test": 0.5}}, "run")
    (axis,) = figure.axes
    lines = {line.get_label(): list(line.get_ydata()) for line in axis.lines}
    assert lines == {"training networks": [0.5, 0.6], "unseen networks": [0.49, 0.55],
                     "do nothing": [0.5, 0.5]}  # fmt: skip
    assert axis.get_xlabel() == "environment steps" and axis.get_title() == "run"


def test_sb3_maskable_ppo(tmp_path):
    pytest.importorskip("sb3_contrib")
    out = run_example("sb3_maskable_ppo.py", "--short", cwd=tmp_path)
    assert 0.0 <= number(r"greedy return ([\d.]+) on 2 unseen networks", out) <= 1.0


@pytest.mark.slow
def test_own_agent_on_the_benchmark(tmp_path):
    # Slow tier: the suite's oracle reference plays 100 networks (~30 CPU seconds).
    out = run_example("own_agent_on_the_benchmark.py", "--short", cwd=tmp_path)
    assert "task paper, validation split, 100 networks, 1 seed(s)" in out
    assert number(r"do nothing ([\d.]+)", out) == 0.5
    normalised = number(r"normalised (-?[\d.]+)", out)
    assert 0.0 < normalised < 1.0  # above doing nothing, below the oracle
