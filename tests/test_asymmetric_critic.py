"""The guided learner's privileged critic (asymmetric DQN): its losses by hand, that it
reads the truth and the agent does not, the configuration's checks, exact resume, and
that the critic learns (``spikectl.training.learners.asymmetric``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
from test_guided import SHORT as SHORT_GUIDED
from test_guided import guided, without_clocks_or_nan

from spikectl.agents import make_agent
from spikectl.config_errors import ConfigError
from spikectl.contexts import make_splits
from spikectl.training.learners import GuidedConfig
from spikectl.training.learners.asymmetric import (
    asymmetric_losses,
    make_critic,
    told_observations,
)
from spikectl.training.learners.dqn_config import DQNConfig
from spikectl.training.presets import SMOKE
from spikectl.training.run import train


class Fixed(torch.nn.Module):
    """A stand-in network returning fixed values [B, N + 1, n + 1] and recording whether
    it was shown the belief input."""

    def __init__(self, values):
        super().__init__()
        self.values = torch.tensor(values, dtype=torch.float32)
        self.saw_belief = None

    def forward(self, obs_seq):
        self.saw_belief = obs_seq.get("belief")
        return self.values.clone(), None


def sequence(n=2, steps=2):
    return {
        "voltage": torch.full((1, steps + 1, n), -70.0),
        "last_action": torch.full((1, steps + 1), -1),
        "step": torch.arange(steps + 1)[None],
        "target": torch.zeros(1, steps + 1, dtype=torch.long),
        "pattern": torch.zeros(1, steps + 1, steps),
    }


def test_losses_by_hand():
    # Two steps, two neurons: actions -1 (do nothing), 0, 1 at indices 0, 1, 2.
    agent = Fixed([[[0.1, 0.5, 0.2], [0.0, 0.9, 0.3], [0.4, 0.4, 0.4]]])
    critic = Fixed([[[0.6, 0.2, 0.0], [0.7, 0.1, 0.5], [0.9, 0.9, 0.9]]])
    critic_target = Fixed([[[0.3, 0.8, 0.1], [0.2, 0.6, 0.4], [0.5, 0.5, 0.5]]])
    tensors = {
        "obs_seq": sequence(),
        "actions": torch.tensor([[0, 1]]),  # index 1, then index 2
        "rewards": torch.tensor([[1.0, 0.0]]),
        # Neuron 0 illegal at every step: the agent's greedy choice at observation 1
        # is then index 2 (0.3), not index 1 (0.9).
        "legal": torch.tensor([[[True, False, True]]]),
    }
    settings = DQNConfig(gamma=0.5, n_step=1, loss="mse")
    agent_loss, critic_loss, aux, q_values = asymmetric_losses(
        agent, critic, critic_target, tensors, torch.tensor([[1, -1]]), settings
    )
    # The agent regresses onto the critic's target copy at the taken actions.
    expected_agent = ((0.5 - 0.8) ** 2 + (0.3 - 0.4) ** 2) / 2
    # The critic: r_0 + 0.5 U⁻(h_1, s, greedy Q at h_1 = index 2) = 1 + 0.5 * 0.4;
    # the last step is terminal: r_1 + 0.
    expected_critic = ((0.2 - 1.2) ** 2 + (0.5 - 0.0) ** 2) / 2
    assert agent_loss.item() == pytest.approx(expected_agent)
    assert critic_loss.item() == pytest.approx(expected_critic)
    assert aux is None and q_values.shape == (1, 3, 3)
    # Only the critic was shown the truth: neuron 0 excites, neuron 1 inhibits.
    assert agent.saw_belief is None
    np.testing.assert_array_equal(critic.saw_belief[0, 0], [[1, 0, 0], [0, 1, 0]])


def test_told_observations_are_a_certain_belief_at_every_step():
    told = told_observations(sequence(n=3, steps=4), torch.tensor([[0, 1, -1]]))
    assert told["belief"].shape == (1, 5, 3, 3)
    expected = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]  # excites, inhibits, uncertainty
    for step in range(5):
        np.testing.assert_array_equal(told["belief"][0, step], expected)


def test_the_critic_reads_the_truth_and_is_seeded_on_its_own_stream():
    config = guided(SMOKE.with_changes(n_neurons=5), asymmetric_critic=True)
    critic, target = make_critic(config)
    assert critic.sizes.belief_in_input and not config.agent.sizes.belief_in_input
    assert not any(p.requires_grad for p in target.parameters())
    obs = sequence(n=5, steps=3)
    obs["pattern"] = torch.zeros(1, 4, config.env.episode_length)
    values = [critic(told_observations(obs, torch.tensor([signs])))[0]
              for signs in ([1, 0, 0, 0, 0], [0, 0, 0, 0, -1])]  # fmt: skip
    assert not torch.equal(values[0], values[1])
    again, _ = make_critic(config)
    pairs = zip(critic.parameters(), again.parameters(), strict=True)
    assert all(torch.equal(a, b) for a, b in pairs)
    with torch.random.fork_rng(devices=[]):  # the agent's stream would give another critic
        torch.manual_seed(config.train.seed)
        on_agents_stream = make_agent("tdrqn", 5, config.env.episode_length, critic.sizes)
    first = next(iter(critic.parameters()))  # a randomly initialised weight
    assert not torch.equal(first, next(iter(on_agents_stream.parameters())))


def test_configuration_checks():
    with pytest.raises(ConfigError, match="asymmetric_critic.*per-neuron architecture"):
        guided(SMOKE.with_changes(arch="drqn"), asymmetric_critic=True)
    with pytest.raises(ConfigError, match="asymmetric_critic.*belief input"):
        guided(
            SMOKE.with_changes({"agent.sizes.belief_in_input": True}), asymmetric_critic=True
        )
    with pytest.raises(ConfigError, match="asymmetric_critic must be true or false"):
        GuidedConfig(asymmetric_critic="yes")
    guided(SMOKE.with_changes(arch="drqn"))  # without the critic: fine


def test_cli_refuses_an_agent_without_room_for_the_critic(tmp_path, capsys):
    from spikectl.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["train", "guided", "--asymmetric-critic", "--arch", "drqn",
              "--run-dir", str(tmp_path / "run")])  # fmt: skip
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--asymmetric-critic" in line and "drqn" in line
    assert not (tmp_path / "run").exists()  # refused before anything was written


SHORT = dataclasses.replace(
    SHORT_GUIDED, learner=dataclasses.replace(SHORT_GUIDED.learner, asymmetric_critic=True)
)


def test_run_with_the_critic_learns_and_resumes_exactly(tmp_path, interrupt_after_rounds):
    """The critic's TD loss falls as it learns, the agent saves and loads as a plain
    network, and a run with the critic resumes bit for bit."""
    from spikectl.training.torch_files import load_model_weights

    reference = train(SHORT, tmp_path / "reference")
    losses = [row["critic_loss"] for row in reference[1:]]
    assert all(math.isfinite(x) for x in losses) and losses[-1] < losses[0] / 2
    restore = interrupt_after_rounds(3)
    with pytest.raises(KeyboardInterrupt):
        train(SHORT, tmp_path / "killed")
    restore()
    resumed = train(SHORT, tmp_path / "killed", resume=True)
    assert without_clocks_or_nan(resumed) == without_clocks_or_nan(reference)
    plain = make_agent("tdrqn", SHORT.env.n_observed, SHORT.env.episode_length,
                       SHORT.agent.sizes, params=SHORT.env.params)  # fmt: skip
    plain.load_state_dict(load_model_weights(tmp_path / "reference" / "best_model.pt"))
    without = train(
        dataclasses.replace(SHORT, learner=dataclasses.replace(SHORT.learner,
                                                               asymmetric_critic=False)),
        tmp_path / "without",
    )  # fmt: skip
    assert "critic_loss" not in without[0] and "critic_loss" in reference[0]


def test_the_critic_only_needs_the_target_inputs_it_stores():
    from spikectl.training.learners.guided import GuidedDQNLearner

    train_set = make_splits(3, 1, 5, 20, seed=0, n_val=0)[0]
    learner = GuidedDQNLearner(
        guided(SMOKE.with_changes(n_neurons=5), asymmetric_critic=True),
        train_set, np.random.default_rng(0),
    )  # fmt: skip
    assert learner.connectivity_head is None and learner.replay.target_inputs is not None
    assert any(p is q for p in learner.trained for q in learner.critic.parameters())
    assert not any(p is q for p in learner.trained for q in learner.critic_target.parameters())
