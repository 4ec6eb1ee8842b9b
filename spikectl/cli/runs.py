"""``spikectl evaluate``, ``sweep`` and ``plot``: trained runs, grids of them, their figures."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro

from spikectl.experiments.backends import Backend
from spikectl.experiments.slurm import SlurmSettings
from spikectl.training.presets import PRESETS

PresetName = Literal[tuple(PRESETS)]  # type: ignore[valid-type]
"""The name of a preset: the tree's and every registered learner's."""


@dataclass(frozen=True)
class EvaluateCommand:
    """Evaluate a trained agent greedily on its own sets or on any context set."""

    run_dir: Annotated[Path, tyro.conf.Positional]
    """The run directory of a trained agent."""
    contexts: Path | None = None
    """A saved ContextSet (.npz) to evaluate on instead of the run's train/test sets."""
    model: Literal["final", "best"] = "final"
    """Which weights: the final model.pt, or best_model.pt (best validation return)."""
    compiled: bool = False
    """Play the network's compiled policy (NumPy/Numba, what a real-time rig runs)
    instead of the PyTorch network; the returns agree but for near-ties."""
    per_environment: bool = False
    """Play the PyTorch network on each context alone, as `spikectl realtime RUN` does:
    its actions on every CPU (by default one batched forward, as metrics.csv scored it)."""


def evaluate(command: EvaluateCommand) -> None:
    """Print the agent's mean greedy return per split, with its standard error."""
    from spikectl.training.evaluate import evaluate_run

    for result in evaluate_run(
        command.run_dir, command.contexts, command.model, command.compiled,
        command.per_environment,
    ):  # fmt: skip
        print(
            f"{result.name:<24}{result.mean:.3f} +- {result.standard_error:.3f} "
            f"over {result.returns.size} contexts (do nothing {result.do_nothing:.3f})"
        )


@dataclass(frozen=True)
class SweepCommand:
    """Run a grid of training trials; finished trials are skipped, interrupted ones resumed."""

    sweep_dir: Path = Path("runs/sweep")
    """Where the trials' run directories and sweep.json go."""
    preset: Literal["fig4", "fig5"] | None = None
    """The paper's experiments: fig4 (4 architectures x 10 seeds), fig5 (TDRQN x sizes)."""
    config: Path | None = None
    """A JSON sweep file instead: {"base": PRESET, "overrides": {...}, "grid": {...}}."""
    base: PresetName | None = None
    """Replace the sweep's base preset (e.g. quick for a laptop-sized reproduction)."""
    seeds: tuple[int, ...] | None = None
    """Replace the grid's seeds."""
    total_env_steps: int | None = None
    """Override the environment steps of every trial."""
    workers: int = 0
    """Trials run at once; 0 means one per CPU core (slurm: jobs at once, 0 Slurm's limit)."""
    backend: Literal["local", "ray", "slurm"] = "local"
    """local: a process pool; ray: Ray tasks (pip extra ray); slurm: Slurm jobs (extra slurm)."""
    address: str | None = None
    """Ray cluster address (ray backend); a local Ray instance when not given."""
    group_seeds: bool = False
    """Train the trials that differ only in seed and n_train in one process per group."""
    stacked: bool = False
    """With --group-seeds: each group as one stacked computation (pays on a GPU)."""
    slurm: SlurmSettings = SlurmSettings()
    """The jobs' sbatch options (slurm backend): each job is requeued and resumes exactly."""


def sweep(command: SweepCommand) -> None:
    """Run the sweep and print each trial's final train and test return."""
    from spikectl.experiments.sweep import PAPER_SWEEPS, Sweep, load_sweep_file, run_sweep
    from spikectl.files import read_json_file

    if (command.preset is None) == (command.config is None):
        raise ValueError("give exactly one of --preset (fig4, fig5) or --config FILE")
    if command.workers < 0:
        raise ValueError(f"--workers must be >= 0 (0: one per CPU core), got {command.workers}")
    if command.backend != "slurm" and command.slurm != SlurmSettings():
        raise ValueError("--slurm.* options apply to --backend slurm only")
    if command.config is not None:
        description = load_sweep_file(command.config).to_dict()
        if command.base is not None:
            # --base swaps the preset under the file's own overrides, which stay.
            description = read_json_file(command.config)
            if not isinstance(description.get("base", "quick"), str):
                raise ValueError(
                    f"--base: {command.config} holds a whole base config, not a preset name; "
                    "edit its base or drop --base"
                )
    else:
        description = dict(PAPER_SWEEPS[command.preset])
    description = {**description, "grid": dict(description["grid"])}
    if command.base is not None:
        description["base"] = command.base
    if command.seeds is not None:
        description["grid"]["seed"] = list(command.seeds)
    if command.total_env_steps is not None:
        description["overrides"] = {
            **description.get("overrides", {}), "train.total_env_steps": command.total_env_steps,
        }  # fmt: skip
    backend = Backend(
        command.backend, command.workers or None, command.address,
        command.slurm if command.backend == "slurm" else None,
    )  # fmt: skip
    run_sweep(
        Sweep.from_dict(description), command.sweep_dir, backend,
        group_seeds=command.group_seeds, stacked=command.stacked,
    )  # fmt: skip


@dataclass(frozen=True)
class PlotCommand:
    """Draw Figures 3-5, the results tables and an episode raster of a sweep."""

    sweep_dir: Annotated[Path, tyro.conf.Positional]
    """The sweep directory (as given to spikectl sweep)."""
    out_dir: Path | None = None
    """Where to write them (default SWEEP_DIR/figures)."""
    overwrite: bool = False
    """Replace the figures and tables of an earlier plot in --out-dir."""


PLOT_FILES = (
    "figure3.png", "figure4.png", "figure5.png", "raster.png", "results.md", "results.csv",
    "by_training_set_size/results.md", "by_training_set_size/results.csv",
)  # fmt: skip
"""Every file ``experiments.plot.plot_sweep`` may write in its folder."""


def plot(command: PlotCommand) -> None:
    """Write the figures and tables of a sweep from its saved runs."""
    from spikectl.cli.output import refuse_existing
    from spikectl.experiments.plot import plot_sweep
    from spikectl.file_kinds import refuse_other_kinds
    from spikectl.locks import folder_lock

    if command.sweep_dir.exists() and not command.sweep_dir.is_dir():
        # A file where the sweep's folder belongs (a context set, a model): name what it
        # is before any figure folder is attempted inside it.
        expected = "spikectl plot takes a sweep directory (as given to spikectl sweep)"
        refuse_other_kinds(command.sweep_dir, (), expected)
        raise ValueError(f"{command.sweep_dir} is a file; {expected}")
    out_dir = command.out_dir if command.out_dir is not None else command.sweep_dir / "figures"
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"--out-dir: {out_dir} is a file, not a folder")
    with folder_lock(out_dir, "plotting"):
        refuse_existing(out_dir, PLOT_FILES, command.overwrite)
        for path in plot_sweep(command.sweep_dir, out_dir):
            print(f"wrote {path}")
