"""The sim-to-sim gap: each controller's return in spikectl and in Cleo, per setting.

Plays each controller on the benchmark's unseen test networks (task ``paper``, or its
first --networks) once in spikectl's environment and once in Cleo per setting of
``spikectl.bridges.cleo.SETTINGS``, writes one row per episode to OUT/returns.csv and
prints the table of docs/cleo.md (mean return; the change from spikectl with a paired,
network-by-network 95% bootstrap interval; wall-clock ms per episode). Trained runs are
given by directory (their network selected on validation, best_model.pt, compiled).
Runs in the Cleo virtualenv:

    python benchmarks/cleo_sim_to_sim.py --runs RUN_DIR ... --out docs/results/cleo-sim-to-sim
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import time
from pathlib import Path

import numpy as np

from spikectl.bridges.cleo import SETTINGS, CleoLoop
from spikectl.envs.controller import play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.experiments.stats import bootstrap_ci
from spikectl.experiments.suite import load_split
from spikectl.files import atomic_write_text
from spikectl.training.loaders import load_controller

FIELDS = ("controller", "seed", "setting", "context", "return", "seconds", "same_actions")


def controllers(runs: list[Path], planners: list[str], env) -> list[tuple[str, int, object]]:
    """(name, seed, controller): each trained run, then the named planners."""
    found = []
    for run in runs:
        seed = int(run.name.rsplit("s", 1)[-1]) if run.name[-1].isdigit() else 0
        found.append(("trained TDRQN", seed, load_controller(run, model="best", compiled=True)))
    for name in planners:
        found.append((name, 0, load_controller(name, env=env)))
    return found


def table(rows: list[dict], settings: list[str]) -> str:
    """Markdown: mean return per controller and setting (mean ± sd over seeds where there
    are several), the change from spikectl (paired over networks, bootstrap 95%), ms/episode."""
    names = list(dict.fromkeys(row["controller"] for row in rows))
    lines = [
        "| controller | " + " | ".join(["spikectl", *settings]) + " |",
        "|---|" + "---|" * (len(settings) + 1),
    ]
    for name in names:
        cells = []
        seeds = sorted({row["seed"] for row in rows if row["controller"] == name})

        def returns(setting, seed, name=name):
            """{context: return} of one controller seed in one setting."""
            return {r["context"]: r["return"] for r in rows if r["controller"] == name
                    and r["seed"] == seed and r["setting"] == setting}  # fmt: skip

        for setting in ["spikectl", *settings]:
            if not any(returns(setting, seed) for seed in seeds):
                cells.append("")  # this controller did not play this setting
                continue
            means = np.array([np.mean(list(returns(setting, seed).values())) for seed in seeds])
            cell = f"{means.mean():.3f}" + (f" ± {means.std(ddof=1):.3f}" if len(seeds) > 1 else "")
            if setting != "spikectl":
                gaps = []
                for seed in seeds:  # paired on the networks this setting played
                    played, reference = returns(setting, seed), returns("spikectl", seed)
                    gaps.append([played[c] - reference[c] for c in sorted(played)])
                gap = np.mean(gaps, axis=0)
                interval = bootstrap_ci(gap, np.mean, rng=0)
                cell += (f" ({interval.estimate:+.3f} [{interval.low:+.3f}, "
                         f"{interval.high:+.3f}]; {gap.size})")
            cells.append(cell)
        lines.append(f"| {name} ({len(seeds)} seed{'s' * (len(seeds) > 1)}) | "
                     + " | ".join(cells) + " |")  # fmt: skip
    times = [
        f"{setting}: {1e3 * np.median([r['seconds'] for r in rows if r['setting'] == setting]):.0f}"
        for setting in ["spikectl", *settings]
    ]
    if "ideal" in settings:
        reference = {(r["controller"], r["seed"], r["context"]): r["return"]
                     for r in rows if r["setting"] == "spikectl"}  # fmt: skip
        ideal = [r for r in rows if r["setting"] == "ideal"]
        differ = sum(1 for r in ideal if r["same_actions"] == 0
                     or r["return"] != reference[(r["controller"], r["seed"], r["context"])])
        lines.append("")
        lines.append(f"Ideal setting: {differ} of {len(ideal)} episodes differ from spikectl's "
                     "environment in an action or the return.")
    lines.append("")
    lines.append("Median wall-clock ms per episode (controller included): " + ", ".join(times))
    return "\n".join(lines) + "\n"


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as file:
        rows = list(csv.DictReader(file))
    for row in rows:
        row["seed"], row["context"] = int(row["seed"]), int(row["context"])
        row["return"], row["seconds"] = float(row["return"]), float(row["seconds"])
        row["same_actions"] = "" if row["same_actions"] == "" else int(row["same_actions"])
    return rows


def write_table(paths: list[Path], out: Path, networks: int) -> None:
    """The table of several runs of this script (e.g. one per controller and settings) on
    their first ``networks`` networks, their spikectl rows counted once per controller."""
    rows, seen = [], set()
    for path in paths:
        for row in read_rows(path):
            if row["context"] >= networks:
                continue
            key = (row["controller"], row["seed"], row["setting"], row["context"])
            if key not in seen:
                seen.add(key)
                rows.append(row)
    settings = list(dict.fromkeys(r["setting"] for r in rows if r["setting"] != "spikectl"))
    settings.sort(key=lambda name: list(SETTINGS).index(name))
    text = table(rows, settings)
    atomic_write_text(out / "table.md", text)
    print(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, nargs="*", default=[])
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS))
    parser.add_argument("--planners", nargs="*", default=["identify-and-plan", "oracle"])
    parser.add_argument("--networks", type=int, default=100)
    parser.add_argument("--first", type=int, default=0, help="play networks FIRST..NETWORKS-1")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--table-from", type=Path, nargs="*", default=None,
                        help="only write OUT/table.md from these returns.csv files (merged)")
    args = parser.parse_args()
    if args.table_from:
        write_table(args.table_from, args.out, args.networks)
        return
    contexts = load_split("paper", "test")
    indices = range(args.first, args.networks)
    env = NeuronControlEnv(contexts=contexts)
    loops = {name: CleoLoop(contexts, SETTINGS[name]) for name in args.settings}
    rows: list[dict] = []
    started = time.process_time()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, seed, controller in controllers(args.runs, args.planners, env):
        env_actions = {}
        for context in indices:
            began = time.perf_counter()
            env_actions[context], total = play_episode(env, controller, context)
            rows.append(dict(controller=name, seed=seed, setting="spikectl", context=context,
                             same_actions="", **{"return": total,
                                                 "seconds": time.perf_counter() - began}))
        for setting, loop in loops.items():
            for context in indices:
                episode = loop.play(controller, context)
                same = np.array_equal(episode.actions, env_actions[context])
                rows.append(dict(controller=name, seed=seed, setting=setting, context=context,
                                 same_actions=int(same),
                                 **{"return": episode.total, "seconds": episode.seconds}))
            print(f"{name} seed {seed} {setting}: "
                  f"{np.mean([r['return'] for r in rows[-len(indices):]]):.3f}", flush=True)
            lines = [",".join(FIELDS)] + [",".join(str(row[f]) for f in FIELDS) for row in rows]
            atomic_write_text(args.out / "returns.csv", "\n".join(lines) + "\n")
    cpu_minutes = (time.process_time() - started) / 60
    text = table(rows, args.settings) + (
        f"\n{args.networks} test networks (task paper); {cpu_minutes:.1f} CPU-minutes in all on "
        f"{platform.processor() or platform.machine()} ({os.cpu_count()} cores, shared).\n"
    )
    atomic_write_text(args.out / "table.md", text)
    print(text)


if __name__ == "__main__":
    main()
