"""Sweeps: grid expansion, skipping finished trials, resuming, pool == in-process."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from spikectl.experiments.backends import Backend
from spikectl.experiments.sweep import (
    PAPER_SWEEPS,
    Sweep,
    load_sweep_file,
    run_sweep,
    trial_dirs,
)
from spikectl.training.presets import SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import read_metrics

TINY = SMOKE.with_changes(total_env_steps=8 * 20 * 4, eval_every_episodes=16,
                           checkpoint_every_episodes=16)  # fmt: skip


def test_grid_expands_to_every_combination():
    sweep = Sweep(TINY, {"arch": ["drqn", "tdrqn"], "seed": [0, 1, 2]})
    trials = sweep.trials()
    assert [name for name, _ in trials][:2] == ["arch=drqn-seed=0", "arch=drqn-seed=1"]
    assert len(trials) == 6 and len({name for name, _ in trials}) == 6
    assert {(c.agent.arch, c.train.seed) for _, c in trials} == {
        (a, s) for a in ("drqn", "tdrqn") for s in (0, 1, 2)
    }
    fig5 = Sweep.from_dict(PAPER_SWEEPS["fig5"])
    assert len(fig5.trials()) == 40
    assert {c.env.n_train for _, c in fig5.trials()} == {10, 20, 40, 100}
    assert len(Sweep.from_dict(PAPER_SWEEPS["fig4"]).trials()) == 40


def test_bad_sweeps_are_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown config field 'learning_rat'"):
        Sweep(TINY, {"learning_rat": [1e-3]})
    with pytest.raises(ValueError, match="unknown config field 'env.n_trian'"):
        Sweep(TINY, {"env.n_trian": [3]})
    with pytest.raises(ValueError, match="a group of fields"):
        Sweep(TINY, {"env.params": [{}]})
    with pytest.raises(ValueError, match="non-empty list"):
        Sweep(TINY, {"seed": []})
    with pytest.raises(ValueError, match="unknown base preset"):
        Sweep.from_dict({"base": "huge"})
    path = tmp_path / "sweep.json"
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_sweep_file(path)
    path.write_text(
        json.dumps({"base": "smoke", "grid": {"seed": [0, 1]}, "overrides": {"n_train": 4}})
    )
    sweep = load_sweep_file(path)
    assert sweep.base.env.n_train == 4 and len(sweep.trials()) == 2
    # A sizes override changes only the fields it names.
    one_field = Sweep.from_dict({"base": "smoke", "overrides": {"sizes": {"lstm_hidden": 7}}})
    assert one_field.base.agent.sizes == dataclasses.replace(SMOKE.agent.sizes, lstm_hidden=7)


def test_sweep_files_name_fields_flat_dotted_or_nested():
    """Sweep files before the tree named fields flat; the tree's dotted paths and nested
    objects say the same, and a grid may run over environment variants."""
    flat = Sweep.from_dict({"base": "smoke",
                            "overrides": {"n_train": 4, "sizes": {"lstm_hidden": 7}},
                            "grid": {"seed": [0, 1], "arch": ["drqn"]}})  # fmt: skip
    dotted = Sweep.from_dict({"base": "smoke",
                              "overrides": {"env.n_train": 4, "agent.sizes.lstm_hidden": 7},
                              "grid": {"train.seed": [0, 1], "agent.arch": ["drqn"]}})  # fmt: skip
    nested = Sweep.from_dict({"base": "smoke",
                              "overrides": {"env": {"n_train": 4},
                                            "agent": {"sizes": {"lstm_hidden": 7}}},
                              "grid": {"seed": [0, 1], "arch": ["drqn"]}})  # fmt: skip
    assert flat.base == dotted.base == nested.base
    assert [c for _, c in flat.trials()] == [c for _, c in dotted.trials()]
    variants = Sweep.from_dict({
        "base": "smoke",
        "grid": {"env.id": ["spikectl/NeuronControl-v0", "spikectl/NeuronControlNoisy-v0"],
                 "env.extensions.observation_noise_mV": [1.0]},
    })  # fmt: skip
    noise = {name: config.env.extensions.observation_noise_mV for name, config in variants.trials()}
    assert set(noise.values()) == {1.0} and len(noise) == 2
    # One directory per trial: the ids' "/" does not nest them.
    assert "env.id=spikectl_NeuronControlNoisy-v0-env.extensions.observation_noise_mV=1.0" in noise
    # The committed results' sweep files (flat names, grids over arch) still load.
    for path in sorted(Path("docs/results").glob("*/sweep*.json")):
        assert load_sweep_file(path).trials()


@pytest.mark.slow  # 30 s; the sweep command line stays in the default run
def test_sweep_runs_skips_and_resumes(tmp_path):
    sweep = Sweep(TINY, {"arch": ["drqn", "tdrqn"], "seed": [0, 1]})
    results = run_sweep(sweep, tmp_path, Backend(workers=2), echo=lambda line: None)
    assert [r["status"] for r in results] == ["trained"] * 4
    dirs = trial_dirs(tmp_path)
    assert len(dirs) == 4
    # The pool's result equals training the same config in this process.
    name, config = sweep.trials()[3]
    direct = train(config.with_changes(torch_threads=1), tmp_path / "direct")
    pooled = read_metrics(tmp_path / "trials" / name)
    assert [r["test_return"] for r in pooled] == [r["test_return"] for r in direct]
    # Again: everything is done, nothing runs.
    again = run_sweep(sweep, tmp_path, Backend(workers=2), echo=lambda line: None)
    assert [r["status"] for r in again] == ["skipped (done)"] * 4
    # An interrupted trial (final weights missing, checkpoint present) resumes.
    (dirs[0] / "model.pt").unlink()
    resumed = run_sweep(sweep, tmp_path, Backend(workers=1), echo=lambda line: None)
    assert sorted(r["status"] for r in resumed) == ["resumed"] + ["skipped (done)"] * 3
    with pytest.raises(ValueError, match="another sweep"):
        run_sweep(Sweep(TINY, {"seed": [5]}), tmp_path, echo=lambda line: None)


def test_sweep_command_line(tmp_path, capsys):
    from spikectl.cli import main

    path = tmp_path / "sweep.json"
    description = {
        "base": "smoke",
        "overrides": {"total_env_steps": 8 * 20 * 2},
        "grid": {"seed": [3]},
    }
    path.write_text(json.dumps(description))
    main(["sweep", "--config", str(path), "--sweep-dir", str(tmp_path / "s"), "--workers", "1"])
    out = capsys.readouterr().out
    assert "1 trials" in out and "seed=3: trained" in out
    with pytest.raises(SystemExit):
        main(["sweep", "--sweep-dir", str(tmp_path / "t")])
    assert "exactly one of --preset" in capsys.readouterr().err


def test_base_flag_keeps_the_sweep_files_overrides(tmp_path, capsys):
    """--base swaps the preset under a sweep file; the file's overrides still apply."""
    from spikectl.cli import main

    path = tmp_path / "sweep.json"
    description = {
        "base": "paper",
        "overrides": {"n_train": 7, "total_env_steps": 8 * 20 * 2},
        "grid": {"seed": [0]},
    }
    path.write_text(json.dumps(description))
    args = ["sweep", "--config", str(path), "--base", "smoke", "--workers", "1"]
    main([*args, "--sweep-dir", str(tmp_path / "s")])
    config = json.loads((tmp_path / "s/trials/seed=0/config.json").read_text())
    assert config["env"]["n_train"] == 7  # the override
    assert config["env"]["n_neurons"] == SMOKE.env.n_neurons  # the new base
    path.write_text(json.dumps({**description, "base": SMOKE.to_dict()}))
    with pytest.raises(SystemExit):
        main([*args, "--sweep-dir", str(tmp_path / "t")])
    assert "holds a whole base config" in capsys.readouterr().err


@pytest.mark.slow  # 16 s
def test_plot_a_sweep(tmp_path, capsys):
    from spikectl.cli import main

    sweep = Sweep(TINY, {"arch": ["drqn", "tdrqn"], "n_train": [3, 6], "seed": [0]})
    run_sweep(sweep, tmp_path, Backend(workers=2), echo=lambda line: None)
    main(["plot", str(tmp_path)])
    out = capsys.readouterr().out
    for name in ("figure3.png", "figure4.png", "figure5.png", "results.md", "raster.png"):
        assert name in out
        assert next((tmp_path / "figures").rglob(name)).stat().st_size > 0
    table = (tmp_path / "figures" / "results.md").read_text()
    assert "drqn" in table and "tdrqn" in table


def test_figure3_contexts_are_regenerated_when_a_trial_kept_only_its_metrics(tmp_path):
    from spikectl.contexts import ContextSet
    from spikectl.experiments.plot import training_contexts
    from spikectl.training.run_files import read_config
    from spikectl.training.run_sets import TRAIN_FILE

    run_dir = tmp_path / "run"
    config = TINY.with_changes(n_train=5, context_seed=3)
    train(config, run_dir)
    saved = ContextSet.load(run_dir / TRAIN_FILE)
    (run_dir / TRAIN_FILE).unlink()  # as in docs/results/: config and metrics only
    assert training_contexts(run_dir, read_config(run_dir).to_dict()) == saved


@pytest.mark.slow
def test_ray_backend_gives_the_same_results_as_the_local_pool(tmp_path, assert_same_trials):
    pytest.importorskip("ray")
    sweep = Sweep(TINY, {"arch": ["drqn", "tdrqn"], "seed": [0]})
    run_sweep(sweep, tmp_path / "local", Backend(workers=2), echo=lambda line: None)
    results = run_sweep(sweep, tmp_path / "ray", Backend("ray", workers=2), echo=lambda line: None)
    assert [r["status"] for r in results] == ["trained", "trained"]
    assert_same_trials(tmp_path / "local", tmp_path / "ray")


def test_unknown_backend():
    with pytest.raises(ValueError, match="backend must be 'local', 'ray' or 'slurm', got 'dask'"):
        run_sweep(Sweep(TINY, {"seed": [0]}), "unused", Backend("dask"))
