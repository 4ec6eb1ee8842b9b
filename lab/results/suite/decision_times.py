"""Add ``decision_p50_ms`` and ``decision_p99_ms`` to committed ``spikectl benchmark`` CSVs
whose rows were written before the benchmark timed decisions, without playing the scores
again: for each row of a registered controller (do-nothing, random, oracle,
identify-and-plan, ...), the same timing the benchmark now does (one environment, the
task's first 10 networks after a warm-up episode, each decision's CPU time;
``spikectl.cli.benchmark.decision_percentiles``). A row of a run directory (its
weights are not committed) is timed with the network its ``config.json`` beside the CSV
describes, built for the task's size at fresh weights: a forward pass costs the same
whatever the weights. Every other column stays as it was.

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


def architecture_factory(config_dir: Path, model: str, version: int):
    """task name -> (seed -> the greedy controller of a fresh network of the run's
    architecture, built for the task's observed n; its compiled policy where the row's
    ``model`` says so)."""
    import torch

    from spikectl.agents import make_agent
    from spikectl.agents.greedy import GreedyController
    from spikectl.experiments import suite
    from spikectl.training.run_files import read_config

    config = read_config(config_dir)
    torch.set_num_threads(1)

    def make(name: str):
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            network = make_agent(config.agent.arch, suite.task(name, version).n_observed,
                                 config.env.episode_length, config.agent.sizes,
                                 params=config.env.params)  # fmt: skip
        if "compiled" in model:
            from spikectl.agents.compiled import CompiledPolicy

            policy = CompiledPolicy.from_network(network)
            return lambda seed: policy
        controller = GreedyController(network, per_environment="per-environment" in model)
        return lambda seed: controller

    return make


def timed_rows(path: Path, episodes: int) -> list[dict]:
    """The rows of ``path`` with their decision-time columns filled."""
    rows = list(csv.DictReader(path.open()))
    for row in rows:
        registered = row["controller"] in CONTROLLERS
        learned = (path.parent / "config.json").is_file() and not registered
        if row.get("decision_p99_ms") or not (registered or learned):
            row.setdefault("decision_p50_ms", "")
            row.setdefault("decision_p99_ms", "")
            continue
        command = BenchmarkCommand(row["controller"] if registered else "do-nothing",
                                   task=(row["task"],), suite=int(row["suite_version"]),
                                   split=row["split"], decision_episodes=episodes)  # fmt: skip
        make = (controller_factory(command, [row["task"]]) if registered
                else architecture_factory(path.parent, row["model"], command.suite))
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
