"""The training loop knows nothing of Q-learning: a learner that is not DQN plugs in.

``CountingLearner`` is the smallest learner the protocol allows: its network prefers
"do nothing" by a learned margin that it moves each update; the loop must collect,
evaluate, write metrics with its own column, save its network, checkpoint its state
and resume it exactly, alone and as a group's seeds, without knowing what it is.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from spikectl.training import run as run_module
from spikectl.training.learners.looped import LoopedLearners
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.presets import SMOKE
from spikectl.training.run import train, train_seeds
from spikectl.training.run_files import CLOCK_FIELDS, RunDirError, read_metrics
from spikectl.training.torch_files import load_model_weights

CONFIG = SMOKE.with_changes(total_env_steps=6 * 20 * 8, eval_every_episodes=16,
                            checkpoint_every_episodes=16)  # fmt: skip


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

    def __init__(self, config, train_set, rng, diverge_at: int | None = None) -> None:
        self.network = MarginNetwork(config.env.n_observed + 1)
        self.rng, self.updates, self.seen, self.diverge_at = rng, 0, 0, diverge_at

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


@pytest.fixture
def counting(monkeypatch):
    def make_learners(configs, train_sets, rngs, stacked=False, **kwargs):
        seeds = zip(configs, train_sets, rngs, strict=True)
        return LoopedLearners([CountingLearner(c, s, r, **kwargs) for c, s, r in seeds])

    monkeypatch.setattr(run_module, "make_learners", make_learners)
    return make_learners


def test_the_loop_trains_evaluates_and_saves_any_learner(tmp_path, counting):
    rows = train(CONFIG, tmp_path / "run")
    assert [row["episode"] for row in rows] == [0, 16, 32, 48]
    assert [row["updates"] for row in rows] == [0, 2, 4, 6]
    assert [row["loss"] for row in rows] == [0, 16, 32, 48]  # episodes the learner saw
    assert [row["margin"] for row in rows] == [-1.0, -0.5, 0.0, 0.5]
    # Greedy evaluation plays the learner's network: once do nothing wins, exactly 0.5.
    assert rows[-1]["train_return"] == rows[-1]["test_return"] == 0.5
    saved = read_metrics(tmp_path / "run")
    assert math.isnan(saved[0]["epsilon"])  # a DQN column this learner does not fill
    assert [row["margin"] for row in saved] == [-1.0, -0.5, 0.0, 0.5]
    assert load_model_weights(tmp_path / "run" / "model.pt")["margin"].item() == 0.5


def test_the_loop_resumes_any_learner_exactly(tmp_path, counting, monkeypatch):
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


def test_a_group_of_any_learner_and_its_divergence(tmp_path, counting, monkeypatch):
    metrics = train_seeds(CONFIG, [0, 1], tmp_path / "group")
    assert [rows[-1]["updates"] for rows in metrics] == [6, 6]

    def diverging(configs, train_sets, rngs, stacked=False):
        return counting(configs, train_sets, rngs, diverge_at=2)

    monkeypatch.setattr(run_module, "make_learners", diverging)
    with pytest.raises(RunDirError, match=r"training loss became inf at update 2 .*diverged"):
        train(CONFIG, tmp_path / "diverged")
