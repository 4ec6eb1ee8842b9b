"""The training loop knows no learner: the modules of spikectl.training outside
learners/ (the loop, its checkpoints, metrics, logging and the config tree) reach a
learner only through the learner protocol and the registry (the package
``spikectl.training.learners``, its ``protocol`` and ``registry``). Read statically from
the source, function-level imports included."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TRAINING_DIR = Path(__file__).resolve().parent.parent / "spikectl" / "training"
LEARNERS = "spikectl.training.learners"
ALLOWED = {LEARNERS, f"{LEARNERS}.protocol", f"{LEARNERS}.registry"}
LOOP_MODULES = sorted(TRAINING_DIR.glob("*.py"))


def imported_modules(source: str) -> set[str]:
    """Every module an import statement of ``source`` names: ``import a.b`` gives a.b,
    ``from a import b`` gives a and a.b (b may be a module)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def learner_imports(source: str) -> set[str]:
    """The learner modules ``source`` imports besides the protocol and the registry."""
    modules = {m for m in imported_modules(source) if m.startswith(LEARNERS + ".")}
    submodules = {m for m in modules if (TRAINING_DIR / "learners" / f"{part(m)}.py").exists()}
    return {m for m in submodules if ".".join(m.split(".")[:4]) not in ALLOWED}


def part(module: str) -> str:
    """The name of the learners/ module ``module`` lies in (``dqn`` of ``...learners.dqn.X``)."""
    return module.split(".")[3]


def test_the_check_sees_a_learner_import_in_any_form():
    assert learner_imports("from spikectl.training.learners.dqn import DQNLearner") == {
        f"{LEARNERS}.dqn", f"{LEARNERS}.dqn.DQNLearner"
    }  # fmt: skip
    assert learner_imports("def f():\n    from spikectl.training.learners import pqn\n") == {
        f"{LEARNERS}.pqn"
    }
    assert learner_imports("import spikectl.training.learners.q_learning") == {
        f"{LEARNERS}.q_learning"
    }
    allowed = (
        "from spikectl.training.learners import make_learners\n"
        "from spikectl.training.learners.protocol import LossDiverged\n"
        "from spikectl.training.learners.registry import Preset\n"
    )
    assert learner_imports(allowed) == set()


@pytest.mark.parametrize("path", LOOP_MODULES, ids=lambda path: path.name)
def test_a_loop_module_imports_no_learner(path):
    assert {"run.py", "checkpoint.py", "run_logger.py", "config.py"} <= {
        p.name for p in LOOP_MODULES
    }
    assert learner_imports(path.read_text()) == set(), (
        f"{path.name} imports a learner; go through the Learner protocol or the registry"
    )
