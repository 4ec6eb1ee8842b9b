"""Parallel Q-learning without replay (``spikectl.training.learners.pqn``): the Q(lambda)
returns and loss by hand, the LayerNorm option, config checks, determinism, exact
resume, a looped seed group, the command line, and that it learns an easy network."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from spikectl.agents import AgentSizes, make_agent
from spikectl.config_errors import ConfigError
from spikectl.training.config import Experiment
from spikectl.training.learners import PQNConfig
from spikectl.training.learners.dqn import n_step_targets
from spikectl.training.learners.pqn import pqn_losses, q_lambda_returns
from spikectl.training.presets import PRESETS, SMOKE
from spikectl.training.run import train, train_seeds


def pqn(config: Experiment = SMOKE, layer_norm: bool = True, **changes) -> Experiment:
    """``config`` with the PQN learner (its shared settings kept) and LayerNorm."""
    shared = {f.name for f in dataclasses.fields(PQNConfig)}
    settings = {k: v for k, v in dataclasses.asdict(config.learner).items() if k in shared}
    sizes = dataclasses.replace(config.agent.sizes, layer_norm=layer_norm)
    return dataclasses.replace(
        config,
        agent=dataclasses.replace(config.agent, sizes=sizes),
        learner=PQNConfig(**{**settings, **changes}),
    )


def test_q_lambda_returns_by_hand():
    rewards = torch.tensor([[0.0, 0.5, 0.25]])
    bootstrap = torch.tensor([[9.0, 1.0, 2.0, 0.0]])  # observation 3 follows the terminal step
    gamma, lam = 0.5, 0.5
    g2 = 0.25
    g1 = 0.5 + gamma * ((1 - lam) * 2.0 + lam * g2)
    g0 = 0.0 + gamma * ((1 - lam) * 1.0 + lam * g1)
    returns = q_lambda_returns(rewards, bootstrap, gamma, lam)
    assert returns[0].tolist() == pytest.approx([g0, g1, g2])
    # lambda = 0: the one-step target; lambda = 1: the discounted return, no bootstrap.
    one_step = n_step_targets(rewards, bootstrap, gamma, 1)
    assert torch.equal(q_lambda_returns(rewards, bootstrap, gamma, 0.0), one_step)
    monte_carlo = [0.0 + 0.5 * 0.5 + 0.25 * 0.25, 0.5 + 0.5 * 0.25, 0.25]
    returns = q_lambda_returns(rewards, bootstrap, gamma, 1.0)
    assert returns[0].tolist() == pytest.approx(monte_carlo)


class FixedQ(torch.nn.Module):
    """Q-values that do not depend on the input: ``values`` [B, N + 1, n + 1] times a
    learned scale (1 at the start), so the loss has a gradient."""

    def __init__(self, values: torch.Tensor) -> None:
        super().__init__()
        self.values, self.scale = values, torch.nn.Parameter(torch.tensor(1.0))

    def forward(self, obs_seq, state=None):
        return self.values * self.scale, state


def test_pqn_loss_bootstraps_on_the_current_networks_best_legal_value():
    # One episode of two steps, n = 2 neurons (3 actions); neuron 1 (index 2) is illegal.
    values = torch.tensor([[[0.2, 0.4, 9.0],  # obs 0: action 0 (index 1) taken
                            [0.3, 0.1, 9.0],  # obs 1: best legal 0.3; do nothing taken
                            [5.0, 5.0, 5.0]]])  # obs 2 follows the terminal step  # fmt: skip
    tensors = {
        "obs_seq": {},
        "actions": torch.tensor([[0, -1]]),
        "rewards": torch.tensor([[0.0, 0.5]]),
        "legal": torch.tensor([[[True, True, False]]]),
    }
    settings = PQNConfig(gamma=0.9, q_lambda=0.5)
    network = FixedQ(values)
    td, aux = pqn_losses(network, tensors, settings)
    g1 = 0.5
    g0 = 0.0 + 0.9 * (0.5 * 0.3 + 0.5 * g1)
    expected = ((0.4 - g0) ** 2 + (0.3 - g1) ** 2) / 2
    assert aux is None and td.item() == pytest.approx(expected)
    # The returns are targets: the gradient flows through Q(tau_t)[a_t] only.
    td.backward()
    by_hand = (2 * (0.4 - g0) * 0.4 + 2 * (0.3 - g1) * 0.3) / 2
    assert network.scale.grad.item() == pytest.approx(by_hand)


def test_layer_norm_is_an_agent_option_that_changes_nothing_when_off():
    from spikectl.agents.compiled import export_policy

    small = dict(lstm_hidden=8, ff_hidden=16, head_hidden=(16,), tdrqn_head_hidden=(16,),
                 attn_width=8, attn_ff=16, value_hidden=(8,))  # fmt: skip
    for arch in ("drqn", "ddrqn", "dmdrqn", "tdrqn"):
        torch.manual_seed(0)
        plain = make_agent(arch, 4, 10, AgentSizes(**small))
        torch.manual_seed(0)
        normed = make_agent(arch, 4, 10, AgentSizes(**small, layer_norm=True))
        norms = [m for m in normed.modules() if isinstance(m, torch.nn.LayerNorm)]
        plain_norms = [m for m in plain.modules() if isinstance(m, torch.nn.LayerNorm)]
        assert len(norms) > len(plain_norms), arch  # TDRQN's transformer has its own
        # The Linears start the same: a LayerNorm draws nothing at initialisation.
        linears = [m.weight for m in plain.modules() if isinstance(m, torch.nn.Linear)]
        normed_linears = [m.weight for m in normed.modules() if isinstance(m, torch.nn.Linear)]
        assert all(torch.equal(a, b) for a, b in zip(linears, normed_linears, strict=True))
    assert AgentSizes().layer_norm is False
    with pytest.raises(ConfigError, match="layer_norm"):
        AgentSizes(layer_norm=1)
    with pytest.raises(ValueError, match="no LayerNorm"):
        export_policy(normed, "unused.npz")


def test_config_checks_and_round_trip():
    config = pqn(q_lambda=0.3, epochs=2, minibatch_size=3)
    again = Experiment.from_dict(json.loads(json.dumps(config.to_dict())))
    assert again == config and type(again.learner) is PQNConfig
    assert config.to_dict()["learner"]["name"] == "pqn"
    assert config.to_dict()["agent"]["sizes"]["layer_norm"] is True
    for field, value, message in (
        ("q_lambda", 1.5, "q_lambda must lie in"),
        ("epochs", 0, "epochs must be a positive integer"),
        ("minibatch_size", 2.5, "minibatch_size must be an integer, got 2.5"),
        ("gamma", -0.1, "gamma must lie in"),
        ("learning_rate", 0.0, "learning_rate must be > 0"),
        ("loss", "l1", "loss must be"),
        ("explore_do_nothing", 2.0, "explore_do_nothing must lie in"),
        ("max_grad_norm", float("nan"), "max_grad_norm must be finite"),
    ):
        with pytest.raises(ConfigError, match=message) as error:
            PQNConfig(**{field: value})
        assert error.value.path == (field,) and "\n" not in str(error.value)
    with pytest.raises(ConfigError) as error:
        Experiment.from_dict({**config.to_dict(), "learner": {"name": "pqn", "epochs": -1}})
    assert error.value.dotted == "learner.epochs"
    preset = PRESETS["pqn"]
    assert type(preset.learner) is PQNConfig and preset.agent.sizes.layer_norm
    assert preset.env == PRESETS["quick"].env and preset.agent.arch == PRESETS["quick"].agent.arch
    assert abs(preset.total_episodes - PRESETS["quick"].total_episodes) <= preset.train.num_envs


SHORT = pqn(
    SMOKE.with_changes(
        total_env_steps=6 * 20 * 8, eval_every_episodes=16, checkpoint_every_episodes=16
    ),  # fmt: skip
    epochs=2,
    minibatch_size=3,  # 8 episodes a round: minibatches of 3, 3 and 2
    q_lambda=0.65,
    aux_voltage_weight=1.0,
    explore_do_nothing=0.75,
)


def test_same_seed_same_weights_and_exact_resume(
    tmp_path, comparable, assert_same_weights, interrupt_after_rounds
):
    reference = train(SHORT, tmp_path / "reference")
    assert [row["updates"] for row in reference] == [0, 12, 24, 36]  # 2 epochs x 3, a round
    assert all(row["loss"] > 0 and row["aux_loss"] > 0 for row in reference[1:])
    again = train(SHORT, tmp_path / "again")
    assert comparable(again) == comparable(reference)
    assert_same_weights(tmp_path / "again" / "model.pt", tmp_path / "reference" / "model.pt")
    other = train(SHORT.with_changes(seed=1), tmp_path / "other")
    assert comparable(other) != comparable(reference)
    restore = interrupt_after_rounds(3)  # after the checkpoint at episode 16
    with pytest.raises(KeyboardInterrupt):
        train(SHORT, tmp_path / "killed")
    restore()
    resumed = train(SHORT, tmp_path / "killed", resume=True)
    assert comparable(resumed) == comparable(reference)
    for name in ("model.pt", "best_model.pt"):
        assert_same_weights(tmp_path / "killed" / name, tmp_path / "reference" / name)


def test_each_seed_of_a_looped_group_is_the_seed_alone(tmp_path, comparable, assert_same_weights):
    group = train_seeds(SHORT, [0, 1], tmp_path / "group")
    alone = train(SHORT.with_changes(seed=1), tmp_path / "alone")
    assert comparable(group[1]) == comparable(alone)
    assert_same_weights(tmp_path / "group" / "seed=1" / "model.pt", tmp_path / "alone" / "model.pt")


def test_stacked_groups_refuse_the_pqn_learner(tmp_path):
    from spikectl.training.run_files import CONFIG_FILE

    with pytest.raises(ValueError, match="pqn learner has no stacked form"):
        train_seeds(SHORT, [0, 1], tmp_path / "group", stacked=True)
    assert not (tmp_path / "group" / "seed=0" / CONFIG_FILE).exists()  # refused up front


def test_pqn_learns_the_easy_network(tmp_path, easy_network_config):
    """One easy network, short episodes: greedy return clearly above doing nothing (0.5).
    16 updates of 2 episodes a round, as the DQN test's 16 a round (1.0 for seeds 0-4)."""
    config = pqn(easy_network_config, epochs=4, minibatch_size=2, q_lambda=0.65)
    metrics = train(config, tmp_path / "run")
    assert metrics[0]["train_return"] < 0.75
    assert metrics[-1]["train_return"] > 0.9


def test_cli_pqn_preset_help_flags_and_errors(capsys):
    from spikectl.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["train", "pqn", "--help"])
    assert exit_info.value.code == 0
    help_text = capsys.readouterr().out
    assert "--q-lambda" in help_text and "--epochs" in help_text and "PQN" in help_text
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "pqn", "--q-lambda", "2", "--run-dir", "unused"])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--q-lambda" in line and "[0, 1]" in line
    # The quick preset's learner has no lambda; the PQN learner no replay buffer.
    for argv in (["quick", "--q-lambda", "0.5"], ["pqn", "--buffer-size", "100"]):
        with pytest.raises(SystemExit) as exit_info:
            main(["train", *argv, "--run-dir", "unused"])
        assert exit_info.value.code == 2
    capsys.readouterr()


def test_cli_refuses_stacked_pqn_in_one_line(tmp_path, capsys):
    from spikectl.cli import main

    group = tmp_path / "group"
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "pqn", "--seeds", "0", "1", "--stacked", "--run-dir", str(group)])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--stacked" in line and "pqn learner has no stacked form" in line
    assert not group.exists()


def test_evaluation_and_load_agent_rebuild_the_layer_norm_network(tmp_path):
    from spikectl.training.loaders import load_agent

    config = pqn(SMOKE.with_changes(total_env_steps=2 * 20 * 8), epochs=1)
    rows = train(config, tmp_path / "run")
    network = load_agent(tmp_path / "run")
    assert any(isinstance(m, torch.nn.LayerNorm) for m in network.modules())
    assert np.isfinite(rows[-1]["loss"])
