"""``spikectl plot SWEEP_DIR``: every figure and table of a sweep, from its saved runs.

Figures 3-5 and the results tables read only the trials' saved files. The episode
raster replays a saved agent greedily on one unseen network (evaluation, no training).
"""

from __future__ import annotations

import os
from pathlib import Path

from spikectl.contexts import ContextSet
from spikectl.experiments.figures import plot_episode_raster, plot_networks
from spikectl.experiments.report import (
    group_runs,
    load_runs,
    plot_test_curves_by_size,
    plot_training_curves,
    write_results_table,
)
from spikectl.experiments.sweep import trial_dirs
from spikectl.training.config import Experiment, field_value
from spikectl.training.run_sets import TEST_FILE, TRAIN_FILE, generated_contexts


def plot_sweep(
    sweep_dir: str | os.PathLike, out_dir: str | os.PathLike | None = None
) -> list[Path]:
    """Write figure3/4/5 PNGs, results tables and an episode raster; returns their paths."""
    from spikectl.training.evaluate import greedy_episodes
    from spikectl.training.loaders import load_agent

    sweep_dir = Path(sweep_dir)
    out_dir = Path(out_dir) if out_dir is not None else sweep_dir / "figures"
    dirs = trial_dirs(sweep_dir)
    if not dirs:
        raise ValueError(f"{sweep_dir} holds no trials (no trials/*/config.json)")
    runs = load_runs(dirs)
    written = [plot_networks(training_contexts(dirs[0], runs[0].config), out_dir / "figure3.png")]
    by_arch = group_runs(runs, "arch")
    if len({field_value(run.config, "env.id") for run in runs}) > 1:
        # A sweep over environment variants: one group per architecture and variant.
        by_arch = {
            f"{arch} on {env_id.rpartition('/')[2]}": group
            for (arch, env_id), group in group_runs(runs, ("arch", "env.id")).items()
        }
    written.append(plot_training_curves(by_arch, out_dir / "figure4.png").path)
    written += write_results_table(by_arch, out_dir)
    tdrqn = [run for run in runs if field_value(run.config, "agent.arch") == "tdrqn"]
    if len({field_value(run.config, "env.n_train") for run in tdrqn}) > 1:
        by_size = group_runs(tdrqn, "n_train")
        written.append(plot_test_curves_by_size(by_size, out_dir / "figure5.png").path)
        written += write_results_table(by_size, out_dir / "by_training_set_size")
    # The raster: a trained agent (TDRQN when there is one) on its first unseen network.
    chosen, config = next(
        ((d, run.config) for d, run in zip(dirs, runs, strict=True)
         if field_value(run.config, "agent.arch") == "tdrqn"),
        (dirs[0], runs[0].config),
    )  # fmt: skip
    if (chosen / "model.pt").exists():
        test = ContextSet.load(chosen / TEST_FILE)
        episodes = greedy_episodes(load_agent(chosen), test[:1], Experiment.from_dict(config))
        written.append(
            plot_episode_raster(
                test[0].pattern,
                episodes.actions[0],
                episodes.spikes[0],
                test[0].target,
                out_dir / "raster.png",
                title=f"{chosen.name} on unseen test network 0: return {episodes.returns[0]:.3f}",
            )  # fmt: skip
        )
    return written


def training_contexts(run_dir: Path, config: dict) -> ContextSet:
    """A trial's training set: its saved file, or (for results kept without it, such as
    docs/results/) regenerated from the config's seeds exactly as training made it."""
    if (run_dir / TRAIN_FILE).exists() or config["env"]["train_contexts"] is not None:
        return ContextSet.load(run_dir / TRAIN_FILE)
    return generated_contexts(Experiment.from_dict(config))[0]
