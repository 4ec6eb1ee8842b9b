"""The training loop knows nothing of Q-learning: a learner that is not DQN plugs in.

``CountingLearner`` is the smallest learner the protocol allows: its network prefers
"do nothing" by a learned margin that it moves each update; the loop must collect,
evaluate, write metrics with its own column, save its network, checkpoint its state
and resume it exactly, alone and as a group's seeds, without knowing what it is. It is
registered the public way (``spikectl.training.learners.register``), as a learner of
spikectl is: its config class, its implementation and one line.
"""

from __future__ import annotations

import ast
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
import torch

import spikectl
from spikectl.config_errors import ConfigError, check_field_types
from spikectl.training import run as run_module
from spikectl.training.config import Experiment
from spikectl.training.learners import learner_entries, register
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.presets import PRESETS, SMOKE
from spikectl.training.run import METRIC_FIELDS, train, train_seeds
from spikectl.training.run_files import CLOCK_FIELDS, RunDirError, read_metrics
from spikectl.training.torch_files import load_model_weights


@dataclass(frozen=True)
class CountingConfig:
    """The test learner's settings: the update at which its loss diverges (0: never)."""

    name: ClassVar[str] = "counting"
    diverge_at: int = 0

    def __post_init__(self) -> None:
        check_field_types(self)

    def check_episode_length(self, episode_length: int) -> None:
        """Any episode length fits."""


class MarginNetwork(torch.nn.Module):
    """Scores: ``margin`` for do nothing, 0 for every stimulation."""

    def __init__(self, n_actions: int) -> None:
        super().__init__()
        self.n_actions = n_actions
        self.margin = torch.nn.Parameter(torch.tensor(-1.0))

    def step(self, obs, state):
        scores = torch.zeros(obs["voltage"].shape[0], self.n_actions)  # [S, n+1]
        scores[:, 0] = self.margin
        return scores, state


class CountingLearner:
    metric_fields = ("margin",)

    def __init__(self, config, train_set, rng) -> None:
        self.network = MarginNetwork(config.env.n_observed + 1)
        self.rng, self.updates, self.seen = rng, 0, 0
        self.diverge_at = config.learner.diverge_at

    def collection_policy(self, episode):
        rng = self.rng

        def policy(observations, action_mask):
            first_legal = action_mask[:, 1:].argmax(axis=1)  # [S] a legal stimulation
            return np.where(rng.random(action_mask.shape[0]) < 0.5, -1, first_legal)

        return policy

    def observe(self, episodes, contexts):
        self.seen += len(contexts)

    def update(self, episode):
        self.updates += 1
        with torch.no_grad():
            self.network.margin += 0.25  # do nothing wins from the second update on
        if self.diverge_at == self.updates:
            raise LossDiverged(math.inf, self.updates)

    def row_metrics(self, episode):
        margin = self.network.margin.item()
        return {"updates": self.updates, "loss": float(self.seen), "margin": margin}

    def progress(self, episode):
        return {}

    def state_dict(self):
        return {"network": self.network.state_dict(), "updates": self.updates, "seen": self.seen}

    def load_state_dict(self, state):
        self.network.load_state_dict(state["network"])
        self.updates, self.seen = state["updates"], state["seen"]


register(CountingConfig, CountingLearner)  # the one line that adds a learner

CONFIG = dataclasses.replace(
    SMOKE.with_changes(total_env_steps=6 * 20 * 8, eval_every_episodes=16,
                       checkpoint_every_episodes=16),
    learner=CountingConfig(),
)  # fmt: skip


def test_the_loop_trains_evaluates_and_saves_any_learner(tmp_path):
    rows = train(CONFIG, tmp_path / "run")
    assert [row["episode"] for row in rows] == [0, 16, 32, 48]
    assert [row["updates"] for row in rows] == [0, 2, 4, 6]
    assert [row["loss"] for row in rows] == [0, 16, 32, 48]  # episodes the learner saw
    assert [row["margin"] for row in rows] == [-1.0, -0.5, 0.0, 0.5]
    # Greedy evaluation plays the learner's network: once do nothing wins, exactly 0.5.
    assert rows[-1]["train_return"] == rows[-1]["test_return"] == 0.5
    saved = read_metrics(tmp_path / "run")
    # The loop's columns, then the learner's own: no other learner's (no epsilon).
    assert tuple(saved[0]) == (*METRIC_FIELDS, "margin")
    assert [row["margin"] for row in saved] == [-1.0, -0.5, 0.0, 0.5]
    assert load_model_weights(tmp_path / "run" / "model.pt")["margin"].item() == 0.5


def test_the_loop_resumes_any_learner_exactly(tmp_path, monkeypatch):
    reference = train(CONFIG, tmp_path / "reference")
    calls = {"n": 0}
    real_round = run_module.Loop.round

    def round_then_die(self):
        real_round(self)
        calls["n"] += 1
        if calls["n"] == 3:  # after the checkpoint at episode 16, before the one at 32
            raise KeyboardInterrupt

    monkeypatch.setattr(run_module.Loop, "round", round_then_die)
    with pytest.raises(KeyboardInterrupt):
        train(CONFIG, tmp_path / "killed")
    monkeypatch.setattr(run_module.Loop, "round", real_round)
    resumed = train(CONFIG, tmp_path / "killed", resume=True)
    assert [{k: v for k, v in row.items() if k not in CLOCK_FIELDS} for row in resumed] == [
        {k: v for k, v in row.items() if k not in CLOCK_FIELDS} for row in reference
    ]


def test_a_group_of_any_learner_and_its_divergence(tmp_path):
    metrics = train_seeds(CONFIG, [0, 1], tmp_path / "group")
    assert [rows[-1]["updates"] for rows in metrics] == [6, 6]
    diverging = dataclasses.replace(CONFIG, learner=CountingConfig(diverge_at=2))
    with pytest.raises(RunDirError, match=r"training loss became inf at update 2 .*diverged"):
        train(diverging, tmp_path / "diverged")


def test_a_registered_learner_is_in_the_tree_config_json_and_with_changes():
    saved = CONFIG.to_dict()
    assert saved["learner"] == {"name": "counting", "diverge_at": 0}
    assert Experiment.from_dict(saved) == CONFIG
    assert CONFIG.with_changes({"learner.diverge_at": 3}).learner == CountingConfig(3)
    with pytest.raises(ConfigError, match=r"^diverge_at must be an integer, got '3'$") as error:
        CONFIG.with_changes({"learner.diverge_at": "3"})
    assert error.value.dotted == "learner.diverge_at"
    with pytest.raises(ValueError, match="stacked: the counting learner has no stacked form"):
        train_seeds(CONFIG, [0, 1], Path("unused"), stacked=True)


def test_a_learner_is_three_files_of_spikectl():
    """Outside the learners package no module names a learner in its code (identifiers and
    string literals; docstrings may): the registry is the only list of them."""
    package = Path(spikectl.__file__).parent
    learners = package / "training" / "learners"
    names = {entry.name for entry in learner_entries()} - {"dqn", "counting"}
    assert names == {"guided", "pqn"}
    assert set(PRESETS) >= names  # each learner's presets come from its entry
    named = []
    for path in package.rglob("*.py"):
        if learners in path.parents:
            continue
        tree = ast.parse(path.read_text())
        docstrings = {
            id(node.value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        }
        for node in ast.walk(tree):
            words = []
            if isinstance(node, ast.Name):
                words = [node.id]
            elif isinstance(node, ast.Attribute):
                words = [node.attr]
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                words = [node.name]
            elif isinstance(node, ast.alias):
                words = [node.name, node.asname or ""]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                if id(node) not in docstrings:
                    words = [node.value]
            named += [
                (path.name, word) for word in words if any(name in word.lower() for name in names)
            ]
    assert named == []
