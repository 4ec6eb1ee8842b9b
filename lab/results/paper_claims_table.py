"""Tables and Figure 5 of docs/reproduction.md's "The paper's claims at the quick
preset" section, from committed run directories and baseline CSVs.

    python lab/results/paper_claims_table.py docs/results [docs/images/fig5_quick.png]

Prints three markdown tables, each with the baselines of the same 100 unseen test
networks (doing nothing; a random legal policy, mean ± sd over its 10 seeds; the
identify-and-plan controller, no training): Figure 4 (the four architectures, 5 seeds
each), the TDRQN design choices (this project's input and head against the
paper-literal ones), and Figure 5 (TDRQN trained on 10, 20, 40 and 100 networks).
Every trial is the quick preset (264 000 steps) on one Torch thread; wall minutes
depend on what else ran on the machine, core minutes (process CPU time) do not, and
are missing for runs made before spikectl logged CPU time. With a figure path, also
draws Figure 5 (test return against steps, one curve per size).
"""

import csv
import math
import sys
from pathlib import Path

import numpy as np

from spikectl.experiments.report import group_runs, load_runs, plot_test_curves_by_size
from spikectl.experiments.stats import bootstrap_ci, iqm
from spikectl.experiments.sweep import trial_dirs

DESIGN = {
    "ours: target indicator in every neuron's input, dueling do-nothing head": (
        "learn-fast-quick"
    ),
    "paper-literal input: target indicator only after the transformer": "tdrqn-literal-input",
    "pooled do-nothing head (Q of doing nothing without a value stream)": "tdrqn-pooled-head",
}
FIGURE4 = "fig4-fast"
ARCH_LABELS = {"drqn": "DRQN", "ddrqn": "DDRQN", "dmdrqn": "DMDRQN", "tdrqn": "TDRQN"}
SIZES = {
    10: "fig5-quick-n10",
    20: "fig5-quick-n20",
    40: "fig5-quick-n40",
    100: "learn-fast-quick",
}
HEADER = (
    "| {what} | seeds | train | validation | test | test IQM [95% CI] | gap (train − test) "
    "| wall min | core min |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|"
)


def mean_sd(values) -> str:
    values = np.asarray(values, dtype=float)
    if values.size == 0 or np.all(np.isnan(values)):
        return "–"
    return f"{np.nanmean(values):.3f} ± {np.nanstd(values):.3f}"


def minutes(values) -> str:
    values = np.asarray(values, dtype=float) / 60
    return "–" if np.all(np.isnan(values)) else f"{np.nanmean(values):.1f}"


def group_row(label: str, runs) -> str:
    finals = [run.metrics[-1] for run in runs]
    train = np.array([row["train_return"] for row in finals])
    test = np.array([row["test_return"] for row in finals])
    interval = bootstrap_ci(test, iqm, 2000, 0.95, 0)
    return (
        f"| {label} | {len(runs)} | {mean_sd(train)} "
        f"| {mean_sd([row.get('val_return', math.nan) for row in finals])} | {mean_sd(test)} "
        f"| {interval.estimate:.3f} [{interval.low:.3f}, {interval.high:.3f}] "
        f"| {mean_sd(train - test)} | {minutes([row['wall_time_s'] for row in finals])} "
        f"| {minutes([row.get('cpu_time_s', math.nan) for row in finals])} |"
    )


def baseline_rows(results: Path) -> list[str]:
    """Baselines on the test set, from docs/results/baselines/test_n8.csv (per context)."""
    with open(results / "baselines" / "test_n8.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    column = {name: np.array([float(row[name]) for row in rows]) for name in rows[0]}
    random_seeds = _random_seed_spread(results / "baselines" / "test_n8.txt")
    blank = "| – | – | – | – |"
    return [
        f"| doing nothing (baseline) | – | – | – | {column['do_nothing'].mean():.3f} {blank}",
        f"| random legal policy (baseline, 10 seeds) | – | – | – | {random_seeds} {blank}",
        f"| identify-and-plan (no training) | – | – | – "
        f"| {column['identify_and_plan'].mean():.3f} {blank}",
    ]


def _random_seed_spread(table: Path) -> str:
    """The random policy's mean ± sd over seeds, as `spikectl baselines` printed it."""
    for line in table.read_text().splitlines():
        if line.startswith("random"):
            return line.split(maxsplit=1)[1].strip().replace("+-", "±")
    raise ValueError(f"{table} has no random row")


def table(what: str, groups: dict[str, list], results: Path) -> str:
    lines = [HEADER.format(what=what)]
    lines += [group_row(label, runs) for label, runs in groups.items() if runs]
    lines += baseline_rows(results)
    return "\n".join(lines) + "\n"


def runs_of(results: Path, name: str):
    directory = results / name
    return load_runs(trial_dirs(directory)) if directory.exists() else []


def main() -> None:
    results = Path(sys.argv[1])
    by_arch = group_runs(runs_of(results, FIGURE4), "arch")
    architectures = {label: by_arch.get(arch, []) for arch, label in ARCH_LABELS.items()}
    print(table("architecture", architectures, results))
    design = {label: runs_of(results, name) for label, name in DESIGN.items()}
    print(table("TDRQN variant", design, results))
    sizes = {f"{n} training networks": runs_of(results, name) for n, name in SIZES.items()}
    print(table("training set", sizes, results))
    if len(sys.argv) > 2:
        runs = [run for n, name in SIZES.items() for run in runs_of(results, name)]
        plot_test_curves_by_size(group_runs(runs, "n_train"), sys.argv[2])
        print(f"wrote {sys.argv[2]}")


if __name__ == "__main__":
    main()
