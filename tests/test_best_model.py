"""best_model.pt: model selection on the validation set (never on the test set)."""

from __future__ import annotations

import math

import pytest
import torch

from spikectl.training.evaluate import evaluate_run
from spikectl.training.loaders import load_agent
from spikectl.training.presets import SMOKE
from spikectl.training.run import best_on_validation, train
from spikectl.training.run_files import BEST_MODEL_FILE, RunDirError, read_metrics
from spikectl.training.torch_files import model_episode, save_model


def rows(*val_returns: float) -> list[dict]:
    return [{"episode": 10 * k, "val_return": v} for k, v in enumerate(val_returns)]


def test_best_row_is_the_earliest_highest_validation_return():
    metrics = rows(0.5, 0.7, 0.6, 0.7, math.nan)
    assert best_on_validation(metrics) is metrics[1]
    assert best_on_validation(rows(math.nan, math.nan)) is None
    assert best_on_validation([]) is None


def test_best_model_is_the_best_validation_evaluation_exactly(tmp_path):
    """best_model.pt holds the weights of the evaluation with the highest validation
    return: scoring it again gives that row's train, test and validation returns."""
    config = SMOKE.with_changes(n_val=4, learning_rate=3e-3)
    metrics = train(config, tmp_path / "run")
    best = best_on_validation(metrics)
    path = tmp_path / "run" / BEST_MODEL_FILE
    assert model_episode(path) == best["episode"]
    scored = {result.name: result.mean for result in evaluate_run(tmp_path / "run", model="best")}
    assert scored == {"train": best["train_return"], "test": best["test_return"],
                      "validation": best["val_return"]}  # fmt: skip
    # The row it came from is not the last one in this run, so the two files differ.
    assert best is not metrics[-1]
    final = load_agent(tmp_path / "run").state_dict()
    chosen = load_agent(tmp_path / "run", model="best").state_dict()
    assert any(not torch.equal(final[name], chosen[name]) for name in final)


def test_runs_without_a_validation_set_keep_no_best_model(tmp_path):
    train(SMOKE.with_changes(n_val=0, total_env_steps=8 * 20 * 8), tmp_path / "run")
    assert not (tmp_path / "run" / BEST_MODEL_FILE).exists()
    with pytest.raises(RunDirError, match="no best_model.pt.*validation set"):
        load_agent(tmp_path / "run", model="best")
    with pytest.raises(ValueError, match="model must be one of"):
        load_agent(tmp_path / "run", model="latest")


def test_a_resume_restores_the_checkpoints_best_model(tmp_path):
    """A file taken after the checkpoint is dropped (the run writes it again); one that
    is not the checkpoint's best network is moved aside with a warning, never deleted;
    the checkpoint's network is written in its place."""
    from spikectl.training.best_model import LEGACY, kept_network, restore_best_model

    network, other = torch.nn.Linear(2, 2), torch.nn.Linear(2, 2)
    best = kept_network(network, 80)
    path = tmp_path / BEST_MODEL_FILE
    save_model(tmp_path, other, BEST_MODEL_FILE, episode=160)
    restore_best_model(tmp_path, best, 80, network)  # taken after the checkpoint
    assert model_episode(path) == 80 and not list(tmp_path.glob("*set-aside*"))
    restore_best_model(tmp_path, best, 80, network)  # the same network: kept
    save_model(tmp_path, other, BEST_MODEL_FILE, episode=80)
    with pytest.warns(RuntimeWarning, match="other weights.*moved aside"):
        restore_best_model(tmp_path, best, 80, network)
    assert torch.equal(torch.load(path, weights_only=True)["weight"], network.weight)
    path.write_bytes(b"damaged")
    with pytest.warns(RuntimeWarning, match="not a readable.*set-aside-2.pt"):
        restore_best_model(tmp_path, best, 80, network)
    assert (tmp_path / "best_model.set-aside-2.pt").read_bytes() == b"damaged"
    path.write_bytes(b"damaged")  # an older checkpoint cannot restore it: set aside too
    with pytest.warns(RuntimeWarning, match="cannot restore it"):
        restore_best_model(tmp_path, LEGACY, 80, network)
    assert not path.exists()
    restore_best_model(tmp_path, None, 80, network)  # nothing to restore is fine


def test_each_seed_of_a_group_keeps_its_own_best_model(tmp_path):
    from spikectl.training.run import train_seeds

    config = SMOKE.with_changes(n_val=4, total_env_steps=24 * 20 * 8)
    metrics = train_seeds(config, [0, 1], tmp_path / "group")
    for seed, seed_metrics in zip([0, 1], metrics, strict=True):
        run_dir = tmp_path / "group" / f"seed={seed}"
        best = best_on_validation(read_metrics(run_dir))
        assert best["episode"] == best_on_validation(seed_metrics)["episode"]
        assert model_episode(run_dir / BEST_MODEL_FILE) == best["episode"]
        scored = {r.name: r.mean for r in evaluate_run(run_dir, model="best")}
        assert scored["validation"] == best["val_return"]


def test_cli_prints_and_evaluates_the_selected_network(tmp_path, run_cli):
    run = tmp_path / "run"
    out = run_cli("train", "smoke", "--total-env-steps", "1600", "--run-dir", str(run)).stdout
    best = best_on_validation(read_metrics(run))
    assert f"best on val.     {best['train_return']:.3f}   {best['test_return']:.3f}" in out
    assert f"validation {best['val_return']:.3f}, episode {int(best['episode']):,}" in out
    evaluated = run_cli("evaluate", str(run), "--model", "best").stdout
    assert f"validation              {best['val_return']:.3f} +-" in evaluated
    data = (run / BEST_MODEL_FILE).read_bytes()
    (run / BEST_MODEL_FILE).write_bytes(data[: len(data) // 2])  # a truncated copy
    damaged = run_cli("evaluate", str(run), "--model", "best", check=False)
    assert damaged.returncode == 2 and "best_model.pt" in damaged.stderr
    assert "Traceback" not in damaged.stderr
