"""CUDA graphs of a stacked group (spikectl.training.cuda_graphs): the optimizer-state
helpers on the CPU, and on a GPU the captured update against the eager one, the learning
rate schedule inside the graph, and exact resume (skipped without CUDA)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spikectl.config_errors import ConfigError
from spikectl.training.config import Experiment
from spikectl.training.cuda_graphs import (
    CapturedCall,
    eager_optimizer_state,
    make_capturable,
    update_snapshot,
)
from spikectl.training.learners.q_learning import set_learning_rate
from spikectl.training.presets import SMOKE

needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")

TINY = SMOKE.with_changes(total_env_steps=24 * 20 * 8, eval_every_episodes=64,
                          checkpoint_every_episodes=64,
                          learning_rate_end_fraction=0.5)  # fmt: skip


def adam_on(params: list[torch.Tensor]) -> torch.optim.Adam:
    return torch.optim.Adam(params, lr=1e-2)


def adam_steps(params: list[torch.Tensor], optimizer: torch.optim.Adam, steps: int) -> None:
    for step in range(steps):
        optimizer.zero_grad()
        sum(((p - step) ** 2).sum() for p in params).backward()
        optimizer.step()


def test_the_snapshot_puts_back_parameters_and_a_fresh_adam():
    """Warm-up before a capture must leave no trace: after restore, Adam's next steps are
    a fresh Adam's, whether the optimizer had state before or not."""
    torch.manual_seed(0)
    params = [torch.randn(3, 4, requires_grad=True), torch.randn(5, requires_grad=True)]
    reference = [p.detach().clone().requires_grad_() for p in params]
    optimizer, fresh = adam_on(params), adam_on(reference)
    restore = update_snapshot(params, optimizer)
    adam_steps(params, optimizer, 3)  # the warm-up
    assert not torch.equal(params[0], reference[0])
    restore()
    assert all(torch.equal(p, r) for p, r in zip(params, reference, strict=True))
    assert all(float(state["step"]) == 0 for state in optimizer.state.values())
    adam_steps(params, optimizer, 2)
    adam_steps(reference, fresh, 2)
    assert all(torch.equal(p, r) for p, r in zip(params, reference, strict=True))
    # With state already there (a resumed run), restore puts that state back.
    restore = update_snapshot(params, optimizer)
    adam_steps(params, optimizer, 3)
    restore()
    adam_steps(params, optimizer, 1)
    adam_steps(reference, fresh, 1)
    assert all(torch.equal(p, r) for p, r in zip(params, reference, strict=True))


def test_a_capturable_optimizer_saves_as_an_eager_one_and_its_rate_is_filled_in_place():
    params = [torch.randn(4, requires_grad=True)]
    optimizer = adam_on(params)
    adam_steps(params, optimizer, 2)
    eager = optimizer.state_dict()
    make_capturable(optimizer, "cpu")
    make_capturable(optimizer, "cpu")  # idempotent
    rate = optimizer.param_groups[0]["lr"]
    assert isinstance(rate, torch.Tensor) and optimizer.param_groups[0]["capturable"]
    set_learning_rate(optimizer, 0.25)
    assert optimizer.param_groups[0]["lr"] is rate and float(rate) == 0.25
    saved = eager_optimizer_state(optimizer)
    assert saved["param_groups"][0]["lr"] == 0.25 and not saved["param_groups"][0]["capturable"]
    step = saved["state"][0]["step"]
    assert step.device.type == "cpu" and step.dtype == torch.float32 and float(step) == 2
    assert torch.equal(saved["state"][0]["exp_avg"], eager["state"][0]["exp_avg"])
    # It loads into an optimizer that never saw a graph.
    other = adam_on([p.detach().clone().requires_grad_() for p in params])
    other.load_state_dict(saved)
    assert other.param_groups[0]["lr"] == 0.25


def test_the_config_switch_reads_from_old_configs_and_the_flat_form():
    old = TINY.to_dict()
    del old["train"]["cuda_graphs"]
    assert Experiment.from_dict(old).train.cuda_graphs is True
    assert TINY.with_changes(cuda_graphs=False).train.cuda_graphs is False
    for name in ("cuda_graphs", "progress"):  # a string would be truthy: refused
        quoted = TINY.to_dict()
        quoted["train"][name] = "no"
        with pytest.raises(ConfigError, match=f"{name}.*must be true or false, got 'no'"):
            Experiment.from_dict(quoted)


@needs_cuda
def test_a_captured_call_replays_on_new_inputs_and_refuses_other_shapes():
    x = torch.arange(6.0, device="cuda").reshape(2, 3)
    call = CapturedCall(lambda a: {"double": a * 2, "sum": a.sum(1)}, (x,))
    out = call(torch.ones(2, 3, device="cuda"))
    assert torch.equal(out["double"], torch.full((2, 3), 2.0, device="cuda"))
    assert torch.equal(out["sum"], torch.full((2,), 3.0, device="cuda"))
    with pytest.raises(ValueError, match="fixed shapes"):
        call(torch.ones(3, 3, device="cuda"))


def _stacked_group(cuda_graphs: bool, seeds=(0, 1), device: str = "cuda"):
    from spikectl.training.learners.dqn_stacked import StackedDQN
    from spikectl.training.run_sets import generated_contexts

    config = TINY.with_changes(device=device, cuda_graphs=cuda_graphs, aux_voltage_weight=1.0)
    configs = [config.with_changes(seed=s) for s in seeds]
    train_set = generated_contexts(config)[0]
    rngs = [np.random.default_rng(s) for s in seeds]
    return StackedDQN(configs, [train_set] * len(seeds), rngs)


def _fill_replay(group, episodes: int = 16) -> None:
    rng = np.random.default_rng(5)
    n, N = group.configs[0].env.n_neurons, group.configs[0].env.episode_length
    for seed in group.seeds:
        seed.replay.add(
            (rng.random((episodes, N + 1, n)) * 25 - 70).astype(np.float32),
            rng.integers(-1, n, (episodes, N)), rng.random((episodes, N)).astype(np.float32),
            rng.integers(0, n, episodes), rng.integers(0, 2, (episodes, N)).astype(np.int8),
            np.ones((episodes, n + 1), dtype=bool),
        )  # fmt: skip


def test_a_stacked_group_names_the_seed_whose_loss_diverged_and_keeps_its_weights():
    """The seeds' losses come to the host in one transfer per update: a NaN in seed 1's
    is reported as seed 1's first update, before any weight moves."""
    from spikectl.training.learners.protocol import LossDiverged

    group = _stacked_group(False, device="cpu")
    _fill_replay(group)
    losses = group._losses

    def seed_1_diverges(tensors):
        td, aux = losses(tensors)
        return td * torch.tensor([1.0, float("nan")]), aux

    group._losses = seed_1_diverges
    before = {name: value.detach().clone() for name, value in group.online.params.items()}
    with pytest.raises(LossDiverged) as error:
        group.update(0)
    assert (error.value.seed, error.value.update) == (1, 1)
    assert all(torch.equal(group.online.params[k], before[k]) for k in before)
    assert [seed.updates for seed in group.seeds] == [0, 0]


@needs_cuda
def test_the_captured_update_computes_the_eager_update():
    """The same batches through the graph and eagerly (with the same capturable Adam):
    the first update's losses are equal, and after three rounds with a changing learning
    rate the weights differ by far less than they moved. (Not bit for bit: gradients that
    are zero in exact arithmetic, such as an attention key bias's, are rounding noise that
    Adam's normalisation turns into steps of the learning rate's size.)"""
    eager, graphed = _stacked_group(False), _stacked_group(True)
    assert graphed.cuda_graphs and not eager.cuda_graphs
    make_capturable(eager.optimizer, "cuda")
    start = {name: value.detach().clone() for name, value in eager.online.params.items()}
    for group in (eager, graphed):
        _fill_replay(group)
    eager.update(0)
    graphed.update(0)
    for a, b in zip(eager.seeds, graphed.seeds, strict=True):
        assert b.loss_sum == pytest.approx(a.loss_sum, rel=1e-6)
        assert b.aux_loss_sum == pytest.approx(a.aux_loss_sum, rel=1e-6)
    for episode in (8, 16):
        eager.update(episode)
        graphed.update(episode)
    moved = torch.cat([(eager.online.params[k] - start[k]).flatten() for k in start])
    apart = torch.cat(
        [(graphed.online.params[k] - eager.online.params[k]).flatten() for k in start]
    )
    assert float(apart.norm()) < 0.05 * float(moved.norm())
    for a, b in zip(eager.seeds, graphed.seeds, strict=True):
        assert a.updates == b.updates == 6
        assert b.loss_sum == pytest.approx(a.loss_sum, rel=1e-2)


@needs_cuda
def test_the_graph_reads_the_learning_rate_set_after_the_capture():
    """A learning rate of 0 set after the capture leaves the online weights as they were
    (Adam's step is lr times a finite ratio), while the target still moves towards them."""
    from spikectl.training.learners.q_learning import batch_tensors
    from spikectl.training.stacked_update import stack_seeds

    group = _stacked_group(True)
    _fill_replay(group)
    group.update(0)  # captures
    assert group._captured_update is not None
    online = {k: v.detach().clone() for k, v in group.online.params.items()}
    target = {k: v.detach().clone() for k, v in group.target.params.items()}
    tensors = stack_seeds([batch_tensors(seed.replay.sample(4, seed.rng), "cuda")
                           for seed in group.seeds])  # fmt: skip
    set_learning_rate(group.optimizer, 0.0)
    group._captured_update(tensors)
    assert all(torch.equal(group.online.params[k], online[k]) for k in online)
    assert not all(torch.equal(group.target.params[k], target[k]) for k in target)
    set_learning_rate(group.optimizer, 1e-3)
    group._captured_update(tensors)
    assert not all(torch.equal(group.online.params[k], online[k]) for k in online)


@needs_cuda
def test_a_graphed_group_resumes_exactly(tmp_path, monkeypatch):
    """Interrupted after a checkpoint and resumed (a new capture on the loaded state), a
    graphed stacked group equals the uninterrupted graphed group bit for bit."""
    from spikectl.training import run as run_module
    from spikectl.training.run import train_seeds
    from spikectl.training.run_files import read_metrics
    from spikectl.training.torch_files import load_model_weights

    config = TINY.with_changes(device="cuda", checkpoint_every_episodes=16, aux_voltage_weight=1.0)
    train_seeds(config, [0, 1], tmp_path / "whole", stacked=True)
    real_round, calls = run_module.Loop.round, {"n": 0}

    def round_then_stop(self):
        real_round(self)
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(run_module.Loop, "round", round_then_stop)
    with pytest.raises(KeyboardInterrupt):
        train_seeds(config, [0, 1], tmp_path / "stopped", stacked=True)
    monkeypatch.setattr(run_module.Loop, "round", real_round)
    train_seeds(config, [0, 1], tmp_path / "stopped", resume=True, stacked=True)
    for seed in (0, 1):
        run = f"seed={seed}"
        whole = read_metrics(tmp_path / "whole" / run)
        stopped = read_metrics(tmp_path / "stopped" / run)
        for key in ("loss", "aux_loss", "train_return", "test_return"):
            np.testing.assert_array_equal([r[key] for r in stopped], [r[key] for r in whole])
        a = load_model_weights(tmp_path / "whole" / run / "model.pt")
        b = load_model_weights(tmp_path / "stopped" / run / "model.pt")
        assert all(torch.equal(a[k], b[k]) for k in a)
