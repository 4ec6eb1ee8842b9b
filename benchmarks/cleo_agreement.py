"""Cleo agreement: controllers made for a loop, played in spikectl's environment with the
matching extensions and in the Cleo bridge's setting of that loop (docs/cleo.md).

For each --settings name of ``spikectl.bridges.cleo.SETTINGS`` the controllers are made
for ``matching_extensions(setting)`` (the oracle and identify-and-plan plan the latency
and the light; ``random`` is seeded per network) and play the paper task's first
--networks unseen test networks in both simulators. Prints, per setting and controller,
the mean return in each, the largest difference of one episode's returns, and in how
many episodes the two chose the same actions; writes one row per episode to --out
(if given). A run directory among --controllers plays its trained network (--model
final or best).
A controller that refuses a setting (one made for a loop it cannot read) is reported
with its one line. Runs in the Cleo virtualenv:

    PYTHONPATH=$PWD /tmp/venv-cleo/bin/python benchmarks/cleo_agreement.py \
        --settings latency1 latency2 chr2 spikes-only --networks 100
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from spikectl.bridges.cleo import SETTINGS, CleoLoop, matching_extensions
from spikectl.envs.controller import play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.experiments.suite import load_split
from spikectl.training.loaders import load_controller

FIELDS = ("setting", "controller", "context", "spikectl_return", "cleo_return", "same_actions",
          "cpu_seconds")  # fmt: skip


def agreement(
    setting: str, name: str, networks: int, contexts, model: str = "final"
) -> list[dict]:
    """One row per network: ``name`` made for the setting's extensions, in both loops (a
    run directory's ``model``: ``"final"`` or ``"best"``)."""
    env = NeuronControlEnv(contexts=contexts, extensions=matching_extensions(SETTINGS[setting]))
    loop = CleoLoop(contexts, SETTINGS[setting])
    chosen = {"model": model} if Path(name).is_dir() else {}  # a named controller has one
    rows = []
    for context in range(networks):
        started = time.process_time()
        ours = load_controller(name, env=env, seed=context, **chosen)
        actions, total = play_episode(env, ours, context)
        theirs = load_controller(name, env=env, seed=context, **chosen)
        episode = loop.play(theirs, context)
        rows.append({
            "setting": setting, "controller": name, "context": context,
            "spikectl_return": repr(float(total)), "cleo_return": repr(float(episode.total)),
            "same_actions": int(np.array_equal(episode.actions, actions)),
            "cpu_seconds": f"{time.process_time() - started:.3f}",
        })  # fmt: skip
    return rows


def write_rows(rows: list[dict], out: Path) -> None:
    """Every episode so far, one row each, written whole (a temporary file, then renamed)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(out.name + ".partial")
    with open(partial, "w", newline="") as file:
        writer = csv.DictWriter(file, FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    partial.replace(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--settings", nargs="+", default=["latency1", "latency2", "chr2"],
                        choices=list(SETTINGS))  # fmt: skip
    parser.add_argument("--controllers", nargs="+",
                        default=["oracle", "identify-and-plan", "random"])  # fmt: skip
    parser.add_argument("--networks", type=int, default=30)
    parser.add_argument("--model", choices=("final", "best"), default="final",
                        help="which network of a run directory named in --controllers")  # fmt: skip
    parser.add_argument("--out", type=Path, default=None, help="write one row per episode here")
    arguments = parser.parse_args()
    contexts = load_split("paper", "test")
    print("| setting | controller | spikectl | Cleo | largest difference | same actions | CPU s |")
    print("|---|---|---:|---:|---:|---:|---:|")
    rows: list[dict] = []
    for setting in arguments.settings:
        for name in arguments.controllers:
            try:
                played = agreement(setting, name, arguments.networks, contexts, arguments.model)
            except ValueError as error:  # ControllerInputError, ConfigError among them
                print(f"| `{setting}` | {name} | refused: {error} | | | | |", flush=True)
                continue
            rows += played
            if arguments.out is not None:  # what was played is kept if a later one fails
                write_rows(rows, arguments.out)
            ours = np.array([float(row["spikectl_return"]) for row in played])
            theirs = np.array([float(row["cleo_return"]) for row in played])
            same = sum(row["same_actions"] for row in played)
            seconds = sum(float(row["cpu_seconds"]) for row in played)
            print(f"| `{setting}` | {name} | {ours.mean():.4f} | {theirs.mean():.4f} | "
                  f"{np.abs(ours - theirs).max():.1e} | {same}/{len(played)} | {seconds:.0f} |",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
