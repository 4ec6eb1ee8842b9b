"""Read a run directory and plot it.

A run directory (``spikectl train ... --run-dir DIR``) holds ``config.json`` (every
setting), ``metrics.csv`` (one row per evaluation: environment steps, greedy return on
the training, unseen test and validation networks, CPU time, ...) and
``baselines.json`` (doing nothing and a random policy on the same networks).

    python examples/plot_a_run.py runs/tdrqn-guided-seed0 [--out curve.png]
    python examples/plot_a_run.py --short   # trains the smoke preset into ./smoke-*/ first
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
from pathlib import Path

from matplotlib.figure import Figure


def read_run(run_dir: Path) -> tuple[dict, list[dict[str, float]], dict]:
    """(config, metrics rows, baselines) of a run directory."""
    config = json.loads((run_dir / "config.json").read_text())
    with open(run_dir / "metrics.csv", newline="") as handle:
        rows = [{key: float(value) for key, value in row.items() if value != ""}
                for row in csv.DictReader(handle)]  # fmt: skip
    baselines = json.loads((run_dir / "baselines.json").read_text())
    return config, rows, baselines


def draw(rows: list[dict[str, float]], baselines: dict, title: str) -> Figure:
    """Greedy return on each set of networks against environment steps."""
    figure = Figure(figsize=(6.4, 4.0))
    axis = figure.subplots()
    steps = [row["env_steps"] for row in rows]
    for column, label in (("train_return", "training networks"),
                          ("test_return", "unseen networks"),
                          ("val_return", "validation networks")):  # fmt: skip
        if all(column in row for row in rows):
            axis.plot(steps, [row[column] for row in rows], marker=".", label=label)
    nothing = baselines.get("do_nothing", {}).get("test")
    if nothing is not None:
        axis.axhline(nothing, color="0.4", linestyle=":", label="do nothing")
    axis.set_xlabel("environment steps")
    axis.set_ylabel("greedy return")
    axis.set_title(title)
    axis.legend()
    return figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", nargs="?", type=Path)
    parser.add_argument("--out", type=Path, help="default RUN_DIR/curve.png")
    parser.add_argument("--short", action="store_true", help="train the smoke preset first")
    args = parser.parse_args()
    run_dir = args.run_dir
    if args.short:
        from spikectl.cli import main as spikectl

        run_dir = Path(tempfile.mkdtemp(prefix="smoke-", dir="."))
        spikectl(["train", "smoke", "--run-dir", str(run_dir)])
    if run_dir is None:
        parser.error("give a run directory (or --short)")

    config, rows, baselines = read_run(run_dir)
    last = rows[-1]
    print(
        f"{config['agent']['arch']} seed {config['train']['seed']}: {len(rows)} evaluations, "
        f"last at {last['env_steps']:.0f} steps: train {last['train_return']:.3f}, "
        f"unseen {last['test_return']:.3f}"
    )
    figure = draw(rows, baselines, title=run_dir.name)
    out = args.out or run_dir / "curve.png"
    figure.savefig(out, dpi=120, bbox_inches="tight")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
