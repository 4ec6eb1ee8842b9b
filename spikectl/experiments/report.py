"""Figures 4 and 5 and the results table, read from saved run directories only.

Nothing here trains or evaluates: every number comes from a run directory's
``config.json`` and ``metrics.csv`` (written by ``spikectl train``). A *group* is a
label (an architecture, a training-set size, ...) and the runs of that condition, one
per seed; curves and table entries aggregate over the runs of a group.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from spikectl.experiments.figures import save_figure, subplots
from spikectl.experiments.stats import bootstrap_ci, iqm
from spikectl.files import atomic_write_text
from spikectl.training.config import field_value
from spikectl.training.run_files import (
    METRICS_FILE,
    RunDirError,
    read_config,
    read_metrics,
)

DO_NOTHING_RETURN = 0.5
"""Return of never stimulating, on any context (docs/environment.md)."""


class Run(NamedTuple):
    """One saved run: its resolved config (the nested dict of ``Experiment.to_dict``) and
    its metrics.csv rows."""

    config: dict[str, Any]
    metrics: list[dict[str, float]]


RunLike = Run | str | os.PathLike


def load_runs(run_dirs: Iterable[str | os.PathLike]) -> list[Run]:
    """Read ``config.json`` and ``metrics.csv`` of each run directory."""
    runs = []
    for run_dir in run_dirs:
        config = read_config(Path(run_dir)).to_dict()
        try:
            metrics = read_metrics(Path(run_dir))
        except FileNotFoundError:
            raise RunDirError(f"{run_dir} has no {METRICS_FILE} yet (no evaluation)") from None
        if not metrics:
            raise RunDirError(f"{run_dir}/{METRICS_FILE} has no evaluation rows yet")
        runs.append(Run(config, metrics))
    return runs


def group_runs(runs: Iterable[Run], key: str | tuple[str, ...] = "arch") -> dict[Any, list[Run]]:
    """Group runs by a config field, in sorted order: a dotted path (``"agent.arch"``,
    ``"env.n_train"``) or a field's flat name (``"arch"``, ``"n_train"``); a tuple of
    them groups by their values together (tuples as keys)."""
    groups: dict[Any, list[Run]] = {}
    for run in runs:
        if isinstance(key, tuple):
            value = tuple(field_value(run.config, name) for name in key)
        else:
            value = field_value(run.config, key)
        groups.setdefault(value, []).append(run)
    return dict(sorted(groups.items()))


def _resolve(groups: Mapping[Any, Sequence[RunLike]]) -> dict[Any, list[Run]]:
    if not groups:
        raise ValueError("no groups of runs given")
    resolved = {}
    for label, runs in groups.items():
        runs = [run if isinstance(run, Run) else load_runs([run])[0] for run in runs]
        if not runs:
            raise ValueError(f"group {label!r} has no runs")
        resolved[label] = runs
    return resolved


@dataclass(frozen=True)
class Curve:
    """Mean and standard deviation (``ddof=0``) over the runs of one group."""

    steps: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    n_runs: int


def mean_curve(runs: Sequence[Run], column: str) -> Curve:
    """Aggregate one metrics column over runs against ``env_steps``.

    Runs of one condition evaluate at the same environment steps, and then the values
    are averaged step by step. If their grids differ (an unfinished run, a changed
    evaluation interval) every run is linearly interpolated onto the union of their
    steps within the range that all runs cover.
    """
    series = []
    for run in runs:
        if any(column not in row for row in run.metrics):
            raise ValueError(f"the runs' metrics have no column {column!r}")
        steps = np.array([row["env_steps"] for row in run.metrics], dtype=float)
        values = np.array([row[column] for row in run.metrics], dtype=float)
        keep = np.isfinite(values)
        if not keep.any():
            raise ValueError(f"a run of {field_value(run.config, 'arch')} has no finite {column}")
        series.append((steps[keep], values[keep]))
    first = series[0][0]
    if all(np.array_equal(steps, first) for steps, _ in series):
        grid, stacked = first, np.stack([values for _, values in series])
    else:
        start = max(steps[0] for steps, _ in series)
        stop = min(steps[-1] for steps, _ in series)
        grid = np.unique(np.concatenate([steps for steps, _ in series]))
        grid = grid[(grid >= start) & (grid <= stop)]
        stacked = np.stack([np.interp(grid, steps, values) for steps, values in series])
    return Curve(grid, stacked.mean(axis=0), stacked.std(axis=0), len(series))


@dataclass(frozen=True)
class CurvePlot:
    """A written figure and the curves it shows: ``curves[panel][group label]``."""

    path: Path
    curves: dict[str, dict[Any, Curve]]


def _draw_curves(axis, curves: Mapping[Any, Curve], title: str, label_format: str) -> None:
    for label, curve in curves.items():
        (line,) = axis.plot(curve.steps, curve.mean, label=label_format.format(label))
        axis.fill_between(curve.steps, curve.mean - curve.std, curve.mean + curve.std,
                          color=line.get_color(), alpha=0.2, linewidth=0)  # fmt: skip
    axis.axhline(DO_NOTHING_RETURN, color="0.4", linestyle=":", linewidth=1, label="do nothing")
    axis.set_xlabel("environment steps")
    axis.set_ylabel("return")
    axis.set_title(title)
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8)


def draw_training_curves(groups: Mapping[Any, Sequence[RunLike]], title: str = ""):
    """Figure 4 without saving: ``(figure, curves)``, the train panel left and the
    test panel right (a pyplot-free figure: nothing to close)."""
    groups = _resolve(groups)
    curves = {
        panel: {label: mean_curve(runs, f"{panel}_return") for label, runs in groups.items()}
        for panel in ("train", "test")
    }
    figure, (left, right) = subplots(1, 2, figsize=(11, 4), sharey=True)
    _draw_curves(left, curves["train"], "training contexts", "{}")
    _draw_curves(right, curves["test"], "unseen test contexts", "{}")
    if title:
        figure.suptitle(title)
    return figure, curves


def plot_training_curves(
    groups: Mapping[Any, Sequence[RunLike]], path: str | os.PathLike, title: str = ""
) -> CurvePlot:
    """Figure 4: greedy return on the training (left) and unseen test (right) contexts
    against environment steps, one curve per group (e.g. architecture), mean ± standard
    deviation over its runs shaded, the do-nothing level 0.5 dotted."""
    figure, curves = draw_training_curves(groups, title)
    path = save_figure(figure, path)
    return CurvePlot(path, curves)


def draw_test_curves_by_size(groups: Mapping[Any, Sequence[RunLike]], title: str = ""):
    """Figure 5 without saving: ``(figure, curves)``."""
    groups = _resolve(groups)
    curves = {"test": {size: mean_curve(runs, "test_return") for size, runs in groups.items()}}
    figure, axis = subplots(figsize=(6.4, 4.0))
    _draw_curves(axis, curves["test"], title or "unseen test contexts", "{} training contexts")
    return figure, curves


def plot_test_curves_by_size(
    groups: Mapping[Any, Sequence[RunLike]], path: str | os.PathLike, title: str = ""
) -> CurvePlot:
    """Figure 5: return on the unseen test contexts against environment steps, one
    curve per training-set size (the group labels, e.g. ``group_runs(runs,
    "n_train")``), mean ± standard deviation over seeds shaded."""
    figure, curves = draw_test_curves_by_size(groups, title)
    path = save_figure(figure, path)
    return CurvePlot(path, curves)


TABLE_FIELDS = (
    "group", "n_seeds", "env_steps",
    "train_mean", "train_std", "test_mean", "test_std", "gap_mean", "gap_std",
    "train_iqm", "train_iqm_low", "train_iqm_high", "test_iqm", "test_iqm_low", "test_iqm_high",
    "gap_iqm", "gap_iqm_low", "gap_iqm_high", "wall_minutes", "core_minutes",
)  # fmt: skip


def results_table(
    groups: Mapping[Any, Sequence[RunLike]],
    n_resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[str, list[dict[str, Any]]]:
    """Final train and test return of each group (the last evaluation of every run).

    Per group: mean ± standard deviation over seeds (``ddof=0``), the generalisation
    gap train − test (mean and std of the per-seed gaps), and the IQM with its
    stratified-bootstrap percentile interval (``confidence``, ``n_resamples``, from
    ``seed``) for the final train and test returns and the gap; a gap interval above 0
    says the group does better on its training contexts than on unseen ones at that
    confidence; and the mean wall minutes and core minutes (process CPU time, all
    threads) a run took, NaN for runs written before spikectl logged CPU time.
    Returns ``(markdown, rows)``.
    """
    rows = []
    for label, runs in _resolve(groups).items():
        finals = [run.metrics[-1] for run in runs]
        train = np.array([row["train_return"] for row in finals], dtype=float)
        test = np.array([row["test_return"] for row in finals], dtype=float)
        gap = train - test
        row: dict[str, Any] = {
            "group": str(label),
            "n_seeds": len(runs),
            "env_steps": int(min(row["env_steps"] for row in finals)),
            "train_mean": float(train.mean()), "train_std": float(train.std()),
            "test_mean": float(test.mean()), "test_std": float(test.std()),
            "gap_mean": float(gap.mean()), "gap_std": float(gap.std()),
            "wall_minutes": float(np.mean([row["wall_time_s"] for row in finals])) / 60,
            "core_minutes": float(np.mean([row.get("cpu_time_s", math.nan) for row in finals]))
            / 60,
        }  # fmt: skip
        for name, values in (("train", train), ("test", test), ("gap", gap)):
            interval = bootstrap_ci(values, iqm, n_resamples, confidence, seed)
            row[f"{name}_iqm"] = interval.estimate
            row[f"{name}_iqm_low"] = interval.low
            row[f"{name}_iqm_high"] = interval.high
        rows.append(row)
    percent = f"{100 * confidence:g}%"
    lines = [
        f"| group | seeds | env steps | train return | test return | gap (train − test) "
        f"| train IQM [{percent} CI] | test IQM [{percent} CI] | gap IQM [{percent} CI] "
        "| wall min | core min |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['group']} | {row['n_seeds']} | {row['env_steps']} "
            f"| {row['train_mean']:.3f} ± {row['train_std']:.3f} "
            f"| {row['test_mean']:.3f} ± {row['test_std']:.3f} "
            f"| {row['gap_mean']:.3f} ± {row['gap_std']:.3f} "
            f"| {row['train_iqm']:.3f} [{row['train_iqm_low']:.3f}, {row['train_iqm_high']:.3f}] "
            f"| {row['test_iqm']:.3f} [{row['test_iqm_low']:.3f}, {row['test_iqm_high']:.3f}] "
            f"| {row['gap_iqm']:.3f} [{row['gap_iqm_low']:.3f}, {row['gap_iqm_high']:.3f}] "
            f"| {_minutes(row['wall_minutes'])} | {_minutes(row['core_minutes'])} |"
        )
    return "\n".join(lines) + "\n", rows


def _minutes(value: float) -> str:
    return "–" if math.isnan(value) else f"{value:.1f}"


def write_results_table(
    groups: Mapping[Any, Sequence[RunLike]], out_dir: str | os.PathLike, **options: Any
) -> tuple[Path, Path]:
    """Write :func:`results_table` atomically to ``out_dir``/results.md and results.csv
    (``options`` are passed on); returns the two paths."""
    markdown, rows = results_table(groups, **options)
    out_dir = Path(out_dir)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=TABLE_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({key: row[key] for key in TABLE_FIELDS} for row in rows)
    markdown_path, csv_path = out_dir / "results.md", out_dir / "results.csv"
    atomic_write_text(markdown_path, markdown)
    atomic_write_text(csv_path, buffer.getvalue())
    return markdown_path, csv_path
