"""Add ``decision_p50_ms`` and ``decision_p99_ms`` to committed ``spikectl benchmark`` CSVs
whose rows were written before the benchmark timed decisions, without playing the scores
again: for each row of a registered controller (do-nothing, random, oracle,
identify-and-plan, ...), the same timing the benchmark now does (one environment, the
task's first 10 networks after a warm-up episode, each decision's CPU time;
``spikectl.envs.realtime.decision_times``). A row of a run directory (its
weights are not committed) is timed with the network its ``config.json`` beside the CSV
describes, built for the task's size at fresh weights: a forward pass costs the same
whatever the weights. Every other column stays as it was.

    python lab/results/suite/decision_times.py docs/results/suite/oracle.csv ...
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
from pathlib import Path

import numpy as np

from spikectl import load_controller
from spikectl.envs import NeuronControlEnv
from spikectl.envs.realtime import decision_times
from spikectl.experiments import suite
from spikectl.training.config import Experiment

COLUMNS = ("decision_p50_ms", "decision_p99_ms")
REGISTERED = ("do-nothing", "random", "oracle", "identify-and-plan", "witness")


def architecture_controller(config_dir: Path, model: str, n_observed: int):
    """The greedy controller of a fresh network of the run's architecture (its
    ``config.json``), built for ``n_observed`` neurons; its compiled policy where the
    row's ``model`` says so."""
    import torch

    from spikectl.agents import make_agent
    from spikectl.agents.compiled import CompiledPolicy
    from spikectl.agents.greedy import GreedyController

    config = Experiment.from_dict(json.loads((config_dir / "config.json").read_text()))
    torch.set_num_threads(1)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        network = make_agent(config.agent.arch, n_observed, config.env.episode_length,
                             config.agent.sizes, params=config.env.params)  # fmt: skip
    if "compiled" in model:
        return CompiledPolicy.from_network(network)
    return GreedyController(network, per_environment="per-environment" in model)


def percentiles(row: dict, config_dir: Path, episodes: int) -> tuple[str, str]:
    """The row's controller timed as ``spikectl benchmark`` times it: one environment,
    the task's first ``episodes`` networks after a warm-up episode (ms, as written)."""
    task, version = row["task"], int(row["suite_version"])
    env = NeuronControlEnv(contexts=suite.load_split(task, row["split"], version),
                           extensions=suite.task(task, version).extensions)  # fmt: skip
    if row["controller"] in REGISTERED:
        controller = load_controller(row["controller"], env=env, seed=0)
    else:
        controller = architecture_controller(config_dir, row["model"],
                                             suite.task(task, version).n_observed)  # fmt: skip
    seed = suite.suite_version(version).env_seed
    decision_times(env, controller, [0], seed)  # warm-up: compilation, first allocations
    ms = decision_times(env, controller, range(episodes), seed) * 1e3
    return f"{np.percentile(ms, 50):.4f}", f"{np.percentile(ms, 99):.4f}"


def timed_rows(path: Path, episodes: int) -> list[dict]:
    """The rows of ``path`` with their decision-time columns filled."""
    rows = list(csv.DictReader(path.open()))
    for row in rows:
        registered = row["controller"] in REGISTERED
        learned = (path.parent / "config.json").is_file() and not registered
        if row.get(COLUMNS[1]) or not (registered or learned):
            row.update({column: row.get(column, "") for column in COLUMNS})
            continue
        row[COLUMNS[0]], row[COLUMNS[1]] = percentiles(row, path.parent, episodes)
        print(f"{path.name} {row['task']}: p50 {row[COLUMNS[0]]} ms, "
              f"p99 {row[COLUMNS[1]]} ms", flush=True)
    return rows


def write_rows(rows: list[dict], path: Path) -> None:
    """The rows back over ``path`` atomically, the two columns last where they were not."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(buffer.getvalue())
    os.replace(temporary, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csvs", type=Path, nargs="+")
    parser.add_argument("--episodes", type=int, default=10)
    arguments = parser.parse_args()
    for path in arguments.csvs:
        write_rows(timed_rows(path, arguments.episodes), path)


if __name__ == "__main__":
    main()
