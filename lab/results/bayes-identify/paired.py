"""The new identify-and-plan against the old, network by network, from sweep.py's CSVs.

    python lab/results/bayes-identify/paired.py ROWS.csv PER_NETWORK.csv [--old '{}'] \
        [--new '{"named": true}'] [--out paired.csv]

For each task: both settings' mean return and normalised score, CPU s per episode,
decision CPU-time p50/p99 (ROWS.csv), and the mean per-network difference (new - old)
with a 95% bootstrap interval over the networks (10 000 resamples, seed 0;
spikectl.experiments.stats.bootstrap_ci), printed as a Markdown table.
"""

from __future__ import annotations

import argparse
import csv

import numpy as np

from spikectl.experiments.stats import bootstrap_ci


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rows")
    parser.add_argument("per_network")
    parser.add_argument("--old", default="{}")
    parser.add_argument("--new", default='{"named": true}')
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    rows = {(r["task"], r["settings"]): r for r in csv.DictReader(open(args.rows))}
    returns: dict[tuple[str, str], dict[int, float]] = {}
    for r in csv.DictReader(open(args.per_network)):
        returns.setdefault((r["task"], r["settings"]), {})[int(r["context"])] = float(r["return"])
    tasks = list(dict.fromkeys(task for task, _ in rows))
    table = []
    for task in tasks:
        old, new = rows.get((task, args.old)), rows.get((task, args.new))
        if old is None or new is None:
            continue
        a, b = returns[(task, args.old)], returns[(task, args.new)]
        contexts = sorted(a)
        difference = np.array([b[c] - a[c] for c in contexts])
        interval = bootstrap_ci(difference, statistic=np.mean, n_resamples=10_000, rng=0)
        table.append({
            "task": task, "split": new["split"],
            "old_return": old["mean_return"], "old_normalised": old["normalised"],
            "new_return": new["mean_return"], "new_normalised": new["normalised"],
            "difference": round(interval.estimate, 4), "ci_low": round(interval.low, 4),
            "ci_high": round(interval.high, 4),
            "better": int((difference > 1e-12).sum()), "worse": int((difference < -1e-12).sum()),
            "old_cpu_s_per_episode": old["cpu_s_per_episode"],
            "new_cpu_s_per_episode": new["cpu_s_per_episode"],
            "old_decision_cpu_ms_p50": old["decision_cpu_ms_p50"],
            "old_decision_cpu_ms_p99": old["decision_cpu_ms_p99"],
            "new_decision_cpu_ms_p50": new["decision_cpu_ms_p50"],
            "new_decision_cpu_ms_p99": new["decision_cpu_ms_p99"],
        })  # fmt: skip
    print(
        "| task | old: return (normalised) | new: return (normalised) | new − old [95% CI] "
        "| better / worse networks | CPU s / episode old → new | decision p50 / p99 ms, "
        "old → new |"
    )
    print("|---|---|---|---|---|---|---|")
    for t in table:
        print(
            f"| `{t['task']}` | {float(t['old_return']):.3f} ({float(t['old_normalised']):.3f}) "
            f"| {float(t['new_return']):.3f} ({float(t['new_normalised']):.3f}) "
            f"| {t['difference']:+.3f} [{t['ci_low']:+.3f}, {t['ci_high']:+.3f}] "
            f"| {t['better']} / {t['worse']} "
            f"| {t['old_cpu_s_per_episode']} → {t['new_cpu_s_per_episode']} "
            f"| {t['old_decision_cpu_ms_p50']} / {t['old_decision_cpu_ms_p99']} → "
            f"{t['new_decision_cpu_ms_p50']} / {t['new_decision_cpu_ms_p99']} |"
        )
    if args.out and table:
        with open(args.out, "w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(table[0]))
            writer.writeheader()
            writer.writerows(table)


if __name__ == "__main__":
    main()
