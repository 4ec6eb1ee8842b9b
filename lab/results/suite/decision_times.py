"""Add ``decision_p50_ms`` and ``decision_p99_ms`` to committed ``spikectl benchmark`` CSVs
whose rows were written before the benchmark timed decisions, without playing the scores
again: for each row of a registered controller (do-nothing, random, oracle,
identify-and-plan, ...), the same timing the benchmark now does (one environment, the
task's first 10 networks after a warm-up episode, each decision's CPU time;
``spikectl.cli.benchmark.decision_percentiles``). Every other column stays as it was;
rows of run directories are left empty (their weights are not committed).

    python lab/results/suite/decision_times.py docs/results/suite/oracle.csv ...
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

from spikectl.cli.benchmark import (
    CSV_FIELDS,
    BenchmarkCommand,
    controller_factory,
    decision_percentiles,
    write_rows,
)
from spikectl.training.loaders import CONTROLLERS


def timed_rows(path: Path, episodes: int) -> list[dict]:
    """The rows of ``path`` with their decision-time columns filled."""
    rows = list(csv.DictReader(path.open()))
    for row in rows:
        if row.get("decision_p99_ms") or row["controller"] not in CONTROLLERS:
            row.setdefault("decision_p50_ms", "")
            row.setdefault("decision_p99_ms", "")
            continue
        command = BenchmarkCommand(row["controller"], task=(row["task"],),
                                   suite=int(row["suite_version"]), split=row["split"],
                                   decision_episodes=episodes)  # fmt: skip
        make = controller_factory(command, [row["task"]])
        row["decision_p50_ms"], row["decision_p99_ms"] = decision_percentiles(
            make, row["task"], command, command.suite)
        print(f"{path.name} {row['task']}: p50 {row['decision_p50_ms']} ms, "
              f"p99 {row['decision_p99_ms']} ms", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csvs", type=Path, nargs="+")
    parser.add_argument("--episodes", type=int, default=10)
    arguments = parser.parse_args()
    for path in arguments.csvs:
        rows = timed_rows(path, arguments.episodes)
        fields = [field for field in CSV_FIELDS if field in rows[0]]
        write_rows(rows, path, tuple(fields))


if __name__ == "__main__":
    main()
