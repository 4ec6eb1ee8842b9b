"""Tables of docs/training.md's "Learning fast" section, from committed run directories.

    python lab/results/learn_fast_table.py docs/results

Prints the pilots' table and three markdown tables: the before/after table
(environment steps, gradient updates and wall minutes until the unseen-test return
first reaches 0.70), the ablation table (final train / validation / test return,
mean ± sd over seeds and the test IQM with its 95% stratified-bootstrap interval, wall
and core minutes) and the model-selection table (the final network against
best_model.pt, the evaluation with the highest validation return). Every trial ran
on one Torch thread, two trials at a time on the project's 2-core machine.
"""

import math
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.report import load_runs
from spikectl.experiments.stats import bootstrap_ci, iqm
from spikectl.experiments.sweep import trial_dirs
from spikectl.training.run import best_on_validation

THRESHOLD = 0.70


def first_reaching(metrics, column="test_return", threshold=THRESHOLD):
    return next((row for row in metrics if row[column] >= threshold), None)


def mean_sd(values) -> str:
    values = np.asarray(values, dtype=float)
    if np.all(np.isnan(values)):
        return "–"
    return f"{np.nanmean(values):.3f} ± {np.nanstd(values):.3f}"


def core_minutes(row) -> float:
    """Process CPU minutes; runs made before CPU time was logged ran one per core, so
    their wall minutes are their core minutes."""
    seconds = row.get("cpu_time_s", math.nan)
    return (row["wall_time_s"] if math.isnan(seconds) else seconds) / 60


def before_after(groups) -> str:
    lines = [
        f"| run | seeds | final test return | seeds reaching {THRESHOLD} | env steps to "
        f"{THRESHOLD} | updates to {THRESHOLD} | wall minutes to {THRESHOLD} | core minutes "
        f"to {THRESHOLD} | wall minutes in all | core minutes in all |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, runs in groups.items():
        hits = [first_reaching(run.metrics) for run in runs]
        reached = [hit for hit in hits if hit is not None]

        def spread(key, scale=1.0, reached=reached):
            if not reached:
                return "not reached"
            values = [hit[key] * scale for hit in reached]
            return f"{np.median(values):,.0f} ({min(values):,.0f}–{max(values):,.0f})"

        for hit in reached:  # runs before CPU time was logged ran one per core
            if math.isnan(hit.get("cpu_time_s", math.nan)):
                hit["cpu_time_s"] = hit["wall_time_s"]
        minutes = [run.metrics[-1]["wall_time_s"] / 60 for run in runs]
        core = [core_minutes(run.metrics[-1]) for run in runs]
        lines.append(
            f"| {label} | {len(runs)} | {mean_sd([r.metrics[-1]['test_return'] for r in runs])} "
            f"| {len(reached)} of {len(runs)} | {spread('env_steps')} | {spread('updates')} "
            f"| {spread('wall_time_s', 1 / 60)} | {spread('cpu_time_s', 1 / 60)} "
            f"| {np.mean(minutes):.1f} | {np.mean(core):.1f} |"
        )
    return "\n".join(lines) + "\n"


def ablation(groups) -> str:
    lines = [
        "| settings | seeds | updates | wall min | core min | train | validation | test "
        "| test IQM [95% CI] |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, runs in groups.items():
        finals = [run.metrics[-1] for run in runs]
        test = [row["test_return"] for row in finals]
        interval = bootstrap_ci(np.array(test), iqm, 2000, 0.95, 0)
        minutes = np.mean([row["wall_time_s"] / 60 for row in finals])
        core = np.mean([core_minutes(row) for row in finals])
        val = [row.get("val_return", math.nan) for row in finals]
        lines.append(
            f"| {label} | {len(runs)} | {finals[0]['updates']:,.0f} | {minutes:.1f} "
            f"| {core:.1f} | {mean_sd([row['train_return'] for row in finals])} "
            f"| {mean_sd(val)} | {mean_sd(test)} "
            f"| {interval.estimate:.3f} [{interval.low:.3f}, {interval.high:.3f}] |"
        )
    return "\n".join(lines) + "\n"


def selection(groups) -> str:
    """Final network against the one selected on the validation set (best_model.pt)."""
    lines = [
        "| settings | seeds | final: validation | final: test | selected: validation "
        "| selected: test | selected: test IQM [95% CI] | selected: lowest test seed "
        "| selected at episode |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, runs in groups.items():
        finals = [run.metrics[-1] for run in runs]
        chosen = [best_on_validation(run.metrics) for run in runs]
        if any(row is None for row in chosen):
            continue  # runs made before the validation split existed
        test = np.array([row["test_return"] for row in chosen])
        episodes = ", ".join(f"{int(row['episode']):,}" for row in chosen)
        interval = bootstrap_ci(test, iqm, 2000, 0.95, 0)
        lines.append(
            f"| {label} | {len(runs)} | {mean_sd([row['val_return'] for row in finals])} "
            f"| {mean_sd([row['test_return'] for row in finals])} "
            f"| {mean_sd([row['val_return'] for row in chosen])} | {mean_sd(test)} "
            f"| {interval.estimate:.3f} [{interval.low:.3f}, {interval.high:.3f}] "
            f"| {test.min():.3f} | {episodes} |"
        )
    return "\n".join(lines) + "\n"


PILOTS = {
    "A-g09": "2 updates/episode, 240 k steps, gamma 0.9",
    "B-g099": "A with gamma 0.99 (stopped early)",
    "C-g09-tv": "A + target voltage in each neuron's input",
    "D-g09-tv-exp": "C + exploration 75% do-nothing",
    "E-g09-tv-exp-n3": "D + 3-step targets",
    "F-E-aux1": "E + auxiliary voltage loss (weight 1)",
    "G-E-buf2k-eps01": "E + buffer 2 000, epsilon over 10% (stopped early)",
    "H-F-aux3": "F with auxiliary weight 3 (stopped early)",
    "I-F-b4u64": "F with batches of 4 and 4 updates/episode",
    "K-F-lr2e-3": "F with learning rate 2e-3 (stopped early)",
}


def pilots(directory: Path, at_seconds: float = 450.0) -> str:
    """Single-seed pilots scored on the validation set (their test_return column), read
    at the same wall time (linear interpolation between evaluations) and at their end."""
    lines = [
        f"| pilot | change | validation return after {at_seconds / 60:.1f} wall min "
        "| last validation return | updates | wall min |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for name, change in PILOTS.items():
        (run,) = load_runs([directory / name])
        wall = [row["wall_time_s"] for row in run.metrics]
        early = float(np.interp(at_seconds, wall, [row["test_return"] for row in run.metrics]))
        last = run.metrics[-1]
        lines.append(
            f"| {name[0]} | {change} | {early:.3f} "
            f"| {last['test_return']:.3f} | {last['updates']:,.0f} "
            f"| {last['wall_time_s'] / 60:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    results = Path(sys.argv[1])
    print(pilots(results / "learn-fast-pilots"))
    fig4 = trial_dirs(results / "fig4-quick")
    new_quick = trial_dirs(results / "learn-fast-quick")
    before = {
        "old quick preset (0.625 updates/episode, 1 M steps)": load_runs(
            [d for d in fig4 if d.name.startswith("arch=tdrqn")]
        ),
        "old quick, 2 updates/episode (1 M steps)": load_runs(
            trial_dirs(results / "tdrqn-paper-update-ratio")
        ),
        "quick preset of 2026-11-22 (dueling head, constant lr)": load_runs(new_quick),
        "quick preset (pooled head, lr decay)": load_runs(
            trial_dirs(results / "learn-fast-pooled-decay")
        ),
    }
    print(before_after(before))
    old_quick = before["old quick preset (0.625 updates/episode, 1 M steps)"]
    groups = {
        "old quick preset (reference)": old_quick,
        "quick preset of 2026-11-22 (all mechanisms)": load_runs(new_quick),
        "+ pooled do-nothing head": load_runs(trial_dirs(results / "tdrqn-pooled-head")),
        "+ pooled head + lr decay to 0.1 (quick preset)": load_runs(
            trial_dirs(results / "learn-fast-pooled-decay")
        ),
    }
    if trial_dirs(results / "learn-fast-pooled-decay-lr3e-3"):
        groups["+ pooled head + lr 3e-3 decaying to 0.05"] = load_runs(
            trial_dirs(results / "learn-fast-pooled-decay-lr3e-3")
        )
    if trial_dirs(results / "learn-fast-eps01"):
        groups["quick preset with epsilon annealed over 10% (candidate)"] = load_runs(
            trial_dirs(results / "learn-fast-eps01")
        )
    half_width = {
        "quick preset at quarter width, 3 updates/episode (candidate)": [
            "learn-fast-half-width-3upe"
        ],
        "quick preset at quarter width, 4 updates/episode (candidate)": [
            "learn-fast-half-width-4upe",
            "learn-fast-half-width-4upe-seeds3-4",
        ],
    }
    for label, folders in half_width.items():
        dirs = [d for folder in folders for d in trial_dirs(results / folder)]
        if dirs:
            groups[label] = load_runs(dirs)
    removed = {  # ablations of today's preset; the others are of the preset of 2026-11-22
        "learn-fast-without-n-step": "quick preset with 1-step targets (no 3-step)",
        "learn-fast-without-sparse-exploration": "quick preset with uniform exploration",
    }
    for sweep in sorted(results.glob("learn-fast-without-*")):
        if trial_dirs(sweep):
            label = sweep.name.removeprefix("learn-fast-").replace("-", " ")
            if sweep.name in removed:
                label = removed[sweep.name]
            else:
                label = f"preset of 2026-11-22 {label}"
            groups[label] = load_runs(trial_dirs(sweep))
    print(ablation(groups))
    print(selection(groups))


if __name__ == "__main__":
    main()
