"""Issue 10's mechanisms: n-step targets, the auxiliary next-voltage loss, the validation
split, and the quick preset's settings."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spikectl import ContextSet, make_splits
from spikectl.agents import ARCHITECTURES, make_agent, make_voltage_predictor
from spikectl.training.config import Experiment
from spikectl.training.learners import DQNConfig
from spikectl.training.learners.dqn import n_step_targets, td_loss, training_losses
from spikectl.training.presets import PRESETS, SMOKE
from spikectl.training.replay import EpisodeBatchArrays
from spikectl.training.run import train
from spikectl.training.run_files import read_metrics


def test_n_step_targets_by_hand():
    rewards = torch.tensor([[1.0, 2.0, 3.0, 4.0]])  # N = 4
    bootstrap = torch.tensor([[10.0, 20.0, 30.0, 40.0, 0.0]])  # value of observations 0..4
    g = 0.5
    three = n_step_targets(rewards, bootstrap, g, 3)
    expected = [
        1 + g * 2 + g**2 * 3 + g**3 * 40,  # t = 0 bootstraps from observation 3
        2 + g * 3 + g**2 * 4 + g**3 * 0,  # t = 1 would bootstrap from 4: terminal
        3 + g * 4,  # t = 2: only two rewards are left
        4.0,
    ]
    assert three[0].tolist() == pytest.approx(expected)
    one = n_step_targets(rewards, bootstrap, g, 1)
    assert one[0].tolist() == pytest.approx([1 + g * 20, 2 + g * 30, 3 + g * 40, 4.0])
    whole = n_step_targets(rewards, bootstrap, g, 4)  # Monte Carlo returns
    assert whole[0, 0].item() == pytest.approx(1 + g * 2 + g**2 * 3 + g**3 * 4)


def test_one_step_targets_are_the_papers_bit_for_bit():
    generator = torch.Generator().manual_seed(0)
    rewards = torch.rand(5, 60, generator=generator)
    next_q = torch.randn(5, 60, generator=generator)  # values of observations 1..N
    not_done = torch.ones_like(rewards)
    not_done[:, -1] = 0.0
    paper = rewards + 0.99 * not_done * next_q
    bootstrap = torch.cat([torch.zeros(5, 1), next_q], dim=1)
    bootstrap[:, -1] = 0.0
    assert torch.equal(n_step_targets(rewards, bootstrap, 0.99, 1), paper)


def episode_batch(n: int, length: int, seed: int) -> EpisodeBatchArrays:
    rng = np.random.default_rng(seed)
    return EpisodeBatchArrays(
        voltage=rng.uniform(-75, -40, (3, length + 1, n)).astype(np.float32),
        actions=rng.integers(-1, n - 1, (3, length)),
        rewards=rng.random((3, length)).astype(np.float32),
        targets=np.full(3, n - 1),
        patterns=rng.integers(0, 2, (3, length)).astype(np.int8),
        action_masks=np.concatenate([np.ones((3, n), bool), np.zeros((3, 1), bool)], axis=1),
    )


@pytest.mark.parametrize("arch", ARCHITECTURES)
def test_auxiliary_loss_reads_the_encoder_and_leaves_the_td_loss_unchanged(arch):
    config = SMOKE.with_changes(arch=arch, aux_voltage_weight=1.0)
    torch.manual_seed(0)
    online = make_agent(arch, 5, 20, config.agent.sizes)
    target = make_agent(arch, 5, 20, config.agent.sizes)
    predictor = make_voltage_predictor(online)
    batch = episode_batch(5, 20, seed=1)
    td, aux = training_losses(online, target, batch, config.learner, predictor)
    assert torch.equal(td, td_loss(online, target, batch, config.learner))
    # The auxiliary loss is the MSE of the prediction against the next normalised voltage.
    features, _ = online.encode(_seq(batch))
    predicted = predictor(features[:, :-1], torch.as_tensor(batch.actions))
    next_voltage = (torch.as_tensor(batch.voltage[:, 1:]) + 70.0) / 20.0
    assert aux.item() == pytest.approx(((predicted - next_voltage) ** 2).mean().item(), rel=1e-6)
    aux.backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in online.parameters())


def _seq(batch):
    from spikectl.training.learners.q_learning import sequence_observations

    return sequence_observations(batch, "cpu")


def test_auxiliary_predictor_learns_a_hidden_synapse():
    """A TDRQN encoder with the auxiliary head fits the next voltage of a 2-neuron chain
    (0 excites 1): the prediction error falls well below that of predicting no change."""
    from spikectl import simulate

    weights = np.array([[0, 1], [0, 0]], dtype=np.int8)
    generator = np.random.default_rng(0)
    actions = np.where(generator.random((64, 20)) < 0.3, 0, -1)  # stimulate 0 at random
    voltage = np.stack([simulate(weights, a)[0] for a in actions])  # [E, N, n]
    rest = np.full((64, 1, 2), -70.0, dtype=np.float32)
    batch = EpisodeBatchArrays(
        voltage=np.concatenate([rest, voltage], axis=1).astype(np.float32),
        actions=actions,
        rewards=np.zeros((64, 20), np.float32),
        targets=np.ones(64, np.int64),
        patterns=np.zeros((64, 20), np.int8),
        action_masks=np.tile([True, True, False], (64, 1)),
    )
    config = SMOKE.with_changes(n_neurons=2, aux_voltage_weight=1.0)
    torch.manual_seed(0)
    online = make_agent("tdrqn", 2, 20, config.agent.sizes)
    predictor = make_voltage_predictor(online)
    optimizer = torch.optim.Adam([*online.parameters(), *predictor.parameters()], lr=3e-3)
    for _ in range(300):
        _, aux = training_losses(online, online, batch, config.learner, predictor)
        optimizer.zero_grad()
        aux.backward()
        optimizer.step()
    normalised = (batch.voltage + 70.0) / 20.0
    no_change = float(((normalised[:, 1:] - normalised[:, :-1]) ** 2).mean())
    assert aux.item() < 0.1 * no_change


def test_validation_split_is_disjoint_and_leaves_train_and_test_unchanged():
    train, test = make_splits(30, 20, n_neurons=6, episode_length=20, seed=4)
    train3, test3, validation = make_splits(30, 20, n_neurons=6, episode_length=20, seed=4,
                                            n_val=25)  # fmt: skip
    assert train3 == train and test3 == test and len(validation) == 25
    assert not validation.duplicate_topologies(train) and not validation.duplicate_topologies(test)
    assert len({context.weights.tobytes() for context in validation}) == len(validation)
    # The validation set does not depend on the training set's size.
    assert make_splits(10, 20, n_neurons=6, episode_length=20, seed=4, n_val=25)[2] == validation
    with pytest.raises(ValueError, match="n_val"):
        make_splits(3, 3, n_val=-1)


def test_trainer_evaluates_on_the_validation_set(tmp_path):
    config = SMOKE.with_changes(n_step=3, aux_voltage_weight=0.5, total_env_steps=4 * 20 * 8,
                                eval_every_episodes=16)  # fmt: skip
    metrics = train(config, tmp_path / "run")
    validation = ContextSet.load(tmp_path / "run" / "val_contexts.npz")
    assert len(validation) == config.env.n_val
    rows = read_metrics(tmp_path / "run")
    assert all(0.0 <= row["val_return"] <= 1.0 for row in rows)
    assert np.isnan(rows[0]["aux_loss"]) and rows[-1]["aux_loss"] > 0
    assert [row["val_return"] for row in metrics] == [row["val_return"] for row in rows]
    no_val = train(SMOKE.with_changes(n_val=0, total_env_steps=2 * 20 * 8), tmp_path / "no-val")
    assert np.isnan(no_val[-1]["val_return"])
    assert not (tmp_path / "no-val" / "val_contexts.npz").exists()


def test_new_mechanisms_are_off_in_the_paper_preset_and_validated():
    paper = PRESETS["paper"]
    assert paper.learner.n_step == 1 and paper.learner.aux_voltage_weight == 0.0
    with pytest.raises(ValueError, match="n_step"):
        DQNConfig(n_step=0)
    with pytest.raises(ValueError, match="n_step"):
        paper.with_changes(n_step=61)
    with pytest.raises(ValueError, match="aux_voltage_weight"):
        DQNConfig(aux_voltage_weight=float("inf"))
    # Runs saved before the validation split existed (flat configs) load with none.
    saved = {**paper.train.__dict__, **paper.learner.__dict__, **paper.to_dict()["env"],
             **paper.to_dict()["agent"]}  # fmt: skip
    del saved["n_val"], saved["id"], saved["params"], saved["extensions"]
    assert Experiment.from_dict(saved).env.n_val == 0


def test_target_voltage_feature_is_the_targets_normalised_voltage():
    from spikectl.agents.inputs import per_neuron_inputs

    voltage = torch.tensor([[-70.0, -50.0, -60.0], [-80.0, -70.0, -30.0]])  # [B=2, n=3]
    obs = {"voltage": voltage, "last_action": torch.tensor([-1, 0]),
           "target": torch.tensor([1, 2])}  # fmt: skip
    x = per_neuron_inputs(obs, ("target", "target-voltage"), v_rest_mV=-70.0,
                          v_threshold_mV=-50.0, dtype=torch.float32)  # fmt: skip
    assert x.shape == (2, 3, 4)
    assert x[0, :, 3].tolist() == [1.0, 1.0, 1.0]  # target 1 sits at threshold
    assert x[1, :, 3].tolist() == [2.0, 2.0, 2.0]  # target 2 at -30 mV
    assert x[..., :3].equal(
        per_neuron_inputs(
            obs, ("target",), v_rest_mV=-70.0, v_threshold_mV=-50.0, dtype=torch.float32
        )
    )


@pytest.mark.parametrize("arch", ["ddrqn", "tdrqn"])
def test_target_voltage_feature_keeps_the_networks_equivariant(arch):
    net = make_agent(arch, 6, 9, SMOKE.agent.sizes, inputs=("target", "target-voltage"))
    net = net.double()
    generator = torch.Generator().manual_seed(0)
    obs = {
        "voltage": -70 + 30 * torch.rand(2, 5, 6, generator=generator, dtype=torch.float64),
        "target": torch.full((2, 5), 4),
        "pattern": torch.randint(0, 2, (2, 5, 9), generator=generator).double(),
        "step": torch.arange(5).expand(2, 5),
        "last_action": torch.randint(-1, 6, (2, 5), generator=generator),
    }
    q, _ = net(obs)
    perm = torch.tensor([3, 0, 5, 1, 4, 2])
    inverse = torch.argsort(perm)
    moved = dict(obs, voltage=obs["voltage"][..., perm], target=inverse[obs["target"]],
                 last_action=torch.where(obs["last_action"] >= 0,
                                         inverse[obs["last_action"].clamp(min=0)], -1))  # fmt: skip
    q_moved, _ = net(moved)
    torch.testing.assert_close(q_moved[..., 0], q[..., 0])
    torch.testing.assert_close(q_moved[..., 1:], q[..., 1:][..., perm])


@pytest.mark.parametrize("do_nothing", [0.0, 0.75, 1.0])
def test_do_nothing_biased_exploration(do_nothing):
    from spikectl.training.learners.q_learning import EpsilonGreedyPolicy

    class Zero(torch.nn.Module):
        def step(self, obs, state):
            return torch.zeros(obs["voltage"].shape[0], 5), state

    policy = EpsilonGreedyPolicy(Zero(), 1.0, np.random.default_rng(0), "cpu", do_nothing)
    mask = np.tile([True, True, False, True, True], (4000, 1))  # neuron 1 is the target
    obs = {"voltage": np.zeros((4000, 4), np.float32), "target": np.ones(4000),
           "pattern": np.zeros((4000, 3)), "step": np.zeros(4000),
           "last_action": np.full(4000, -1)}  # fmt: skip
    actions = policy(obs, mask)
    assert not np.any(actions == 1)  # never the illegal target
    assert np.mean(actions == -1) == pytest.approx(do_nothing, abs=0.02)
    if do_nothing < 1:
        stimulated = actions[actions >= 0]
        counts = np.bincount(stimulated, minlength=4)[[0, 2, 3]]
        assert counts.min() > 0.8 * counts.max()  # uniform over the legal stimulations
    with pytest.raises(ValueError, match="explore_do_nothing"):
        DQNConfig(explore_do_nothing=1.5)


def test_learning_rate_decays_linearly_and_needs_no_scheduler_state(tmp_path):
    from spikectl.training.checkpoint import read_checkpoint

    config = SMOKE.with_changes(learning_rate=1e-3, learning_rate_end_fraction=0.25,
                                total_env_steps=4 * 20 * 8)  # fmt: skip
    episodes = config.total_episodes

    def rate(config, episode):
        return config.learner.learning_rate_at(episode, config.total_episodes)

    assert rate(config, 0) == 1e-3
    assert rate(config, episodes // 2) == pytest.approx(0.625e-3)
    assert rate(config, episodes) == pytest.approx(0.25e-3)
    assert rate(config, 2 * episodes) == pytest.approx(0.25e-3)  # no overshoot
    # The default is the paper's constant rate, exactly.
    assert rate(SMOKE, episodes) == SMOKE.learner.learning_rate
    assert PRESETS["paper"].learner.learning_rate_end_fraction == 1.0

    decayed = train(config, tmp_path / "decayed")
    # The last round's updates ran at the rate of the episode count before that round.
    (saved,) = read_checkpoint(tmp_path / "decayed" / "checkpoint.pt")["learners"]["seeds"]
    last_round = episodes - config.train.num_envs
    assert {group["lr"] for group in saved["optimizer"]["param_groups"]} == {
        rate(config, last_round)
    }
    constant = train(config.with_changes(learning_rate_end_fraction=1.0), tmp_path / "constant")
    (saved,) = read_checkpoint(tmp_path / "constant" / "checkpoint.pt")["learners"]["seeds"]
    assert {group["lr"] for group in saved["optimizer"]["param_groups"]} == {1e-3}
    assert decayed[-1]["loss"] != constant[-1]["loss"]
    for bad in (1.5, -0.1, float("nan")):
        with pytest.raises(ValueError, match="learning_rate_end_fraction"):
            DQNConfig(learning_rate_end_fraction=bad)
