"""A validation screen of identify-and-plan compositions on one suite task: each variant
played on a range of the task's networks, one row per network appended to a CSV, and
the paired table of every variant in it against a base variant (the research record's
``variants.py`` scripts of iap-chr2, iap-rig and iap-spikes); and :func:`diagnose`, the
same for given controllers (their ``diagnose.py``). Never on the test set."""

from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import IdentifyAndPlan

SPLIT, VERSION = "validation", 2


def subset(task: str, networks: range) -> ContextSet:
    """Networks ``networks`` (consecutive) of ``task``'s validation set (suite v2)."""
    return suite.load_split(task, SPLIT, VERSION)[networks.start : networks.stop]


def timed_returns(contexts: ContextSet, controller, extensions,
                  first: int = 0) -> tuple[np.ndarray, float]:  # fmt: skip
    """(returns [S], CPU seconds): ``controller`` on every network of ``contexts`` under the
    suite's protocol (its environment seed; ``first``: the index of ``contexts``' first
    network in the whole set's batch, whose sub-environment i is seeded ``env_seed + i``)."""
    started = time.process_time()
    episodes = evaluate_policy(contexts, controller, extensions=extensions,
                               seed=suite.suite_version(VERSION).env_seed + first)  # fmt: skip
    return np.asarray(episodes.returns), time.process_time() - started


def play(task: str, contexts: ContextSet, composition, seed: int = 0) -> tuple[np.ndarray, float]:
    """(returns [S], CPU seconds): ``composition`` on every network of ``contexts``, the
    controller seeded ``seed`` (what QMDP's draws read)."""
    extensions = suite.task(task, VERSION).extensions
    controller = IdentifyAndPlan(composition=composition, extensions=extensions, seed=seed)
    return timed_returns(contexts, controller, extensions)


def _write_rows(writer, name: str, networks, values: np.ndarray, cpu: float) -> None:
    """One ``variant,context,return,cpu_s`` row per network, and the run's line."""
    writer.writerows([name, i, f"{v:.6f}", f"{cpu / len(values):.4f}"]
                     for i, v in zip(networks, values, strict=True))  # fmt: skip
    print(f"{name}: {values.mean():.4f} ({cpu:.1f} CPU s)", flush=True)


def screen(out: Path, task: str, networks: range, table: dict, names: list[str],
           base: str = "named") -> None:  # fmt: skip
    """Play each of ``names`` (keys of ``table``, name -> composition, or (composition,
    the controller's seed)) on ``networks``, append their rows to ``out`` and print the
    paired table of everything in it against ``base``."""
    contexts = subset(task, networks)
    new = not out.exists()
    with open(out, "a", newline="") as handle:
        writer = csv.writer(handle)
        if new:
            writer.writerow(["variant", "context", "return", "cpu_s"])
        for name in names:
            entry = table[name]
            values, cpu = play(task, contexts, *(entry if isinstance(entry, tuple) else (entry,)))
            _write_rows(writer, name, networks, values, cpu)
            handle.flush()
    report(out, base)


def report(out: Path, base: str = "named") -> None:
    """The paired table of every variant in ``out`` against ``base``."""
    rows: dict[str, dict[int, float]] = {}
    cpu: dict[str, float] = {}
    with open(out) as handle:
        for row in csv.DictReader(handle):
            rows.setdefault(row["variant"], {})[int(row["context"])] = float(row["return"])
            cpu[row["variant"]] = float(row["cpu_s"])
    reference = rows[base]
    print(
        f"\n| variant | networks | mean return | − {base} [95% CI] | better / worse "
        "| CPU s a network |"
    )
    print("|---|---:|---:|---|---|---:|")
    for name, values in rows.items():
        common = sorted(set(values) & set(reference))
        mine = np.array([values[i] for i in common])
        theirs = np.array([reference[i] for i in common])
        print(
            f"| {name} | {len(common)} | {mine.mean():.4f} | "
            f"{paired_difference_cells(mine - theirs)} | {cpu[name]:.3f} |"
        )


def diagnose(out: Path, contexts: ContextSet, runs: dict, base: str) -> dict[str, np.ndarray]:
    """Play each of ``runs`` (name -> (extensions, controller)) on ``contexts`` under the
    suite's protocol, write one row per network to ``out`` (``variant,context,return,
    cpu_s``) and print the paired table against ``base``. Returns each run's returns."""
    returns = {}
    with open(out, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["variant", "context", "return", "cpu_s"])
        for name, (extensions, controller) in runs.items():
            returns[name], cpu = timed_returns(contexts, controller, extensions)
            _write_rows(writer, name, range(len(contexts)), returns[name], cpu)
            handle.flush()
    print(f"\n| variant | mean return | − {base} [95% CI] | better / worse |")
    print("|---|---:|---|---|")
    for name, values in returns.items():
        print(f"| {name} | {values.mean():.4f} | "
              f"{paired_difference_cells(values - returns[base])} |")  # fmt: skip
    return returns
