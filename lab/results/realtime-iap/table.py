"""This record's tables, from its committed files (markdown, printed).

    python lab/results/realtime-iap/table.py

Per split (``validation.csv``, ``test.csv`` and their per-network files, from
``measure.py play``): each task's mean return under the fast, the real-time and the
target-paths form, and network by network the real-time form − the fast form, on the
test sets also − the named identify-and-plan (docs/results/suite,
``identify-and-plan-per-network.csv``), and the target-paths form − the fast form. Then
the decision times of ``measure.py times`` (``times.csv``), the widths the real-time
form's was chosen from (``widths.csv``, against width 32 network by network), and the
stimulations the target-paths form keeps (``reach.csv``).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from spikectl.experiments.stats import paired_difference_cells

RESULTS = Path(__file__).resolve().parents[3] / "docs" / "results"
HERE = RESULTS / "realtime-iap"
NAMED = RESULTS / "suite" / "identify-and-plan-per-network.csv"
FORMS = ("fast", "realtime", "target-paths")


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def per_network(rows: list[dict], task: str, **match: str) -> np.ndarray:
    """The returns of ``task``'s rows that match, in network order."""
    mine = [r for r in rows if r["task"] == task and all(r[k] == v for k, v in match.items())]
    return np.array([float(r["return"]) for r in sorted(mine, key=lambda r: int(r["context"]))])


def returns_table(split: str) -> str:
    rows = read_csv(HERE / f"{split}.csv")
    networks = read_csv(HERE / f"{split}-per-network.csv")
    named = read_csv(NAMED) if split == "test" else []
    comparisons = [("realtime", "fast"), *([("realtime", "named")] if named else []),
                   ("target-paths", "fast")]  # fmt: skip
    lines = ["| task | " + " | ".join(FORMS) + " | "
             + " | ".join(f"{a} − {b} [95%] | better / worse" for a, b in comparisons) + " |",
             "|---|" + "---:|" * len(FORMS) + "---|---|" * len(comparisons)]  # fmt: skip
    for task in dict.fromkeys(r["task"] for r in rows):
        mean = {r["form"]: float(r["mean_return"]) for r in rows if r["task"] == task}
        cells = [f"{mean[form]:.3f}" for form in FORMS]
        for form, against in comparisons:
            reference = (per_network(named, task, split="test") if against == "named"
                         else per_network(networks, task, form=against))  # fmt: skip
            mine = per_network(networks, task, form=form)
            cells.append(paired_difference_cells(mine - reference) if reference.size
                         else "– | –")  # fmt: skip
        lines.append(f"| {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def times_table() -> str:
    lines = ["| n | form | decisions | p50 (ms) | p99 (ms) | max (ms) |",
             "|---:|---|---:|---:|---:|---:|"]  # fmt: skip
    for r in read_csv(HERE / "times.csv"):
        lines.append(f"| {r['n_neurons']} | {r['form']} | {r['decisions']} | "
                     f"{float(r['decision_p50_ms']):.2f} | {float(r['decision_p99_ms']):.2f} | "
                     f"{float(r['decision_max_ms']):.2f} |")  # fmt: skip
    return "\n".join(lines)


def widths_table() -> str:
    lines = ["| task | width | validation return | − width 32 [95%] | better / worse | "
             "p50 (ms) | p99 (ms) |", "|---|---:|---:|---|---|---:|---:|"]  # fmt: skip
    networks = read_csv(HERE / "widths-per-network.csv")
    for r in read_csv(HERE / "widths.csv"):
        mine = per_network(networks, r["task"], width=r["width"])
        widest = per_network(networks, r["task"], width="32")
        cells = paired_difference_cells(mine - widest) if r["width"] != "32" else "– | –"
        p50, p99 = float(r["decision_p50_ms"]), float(r["decision_p99_ms"])
        lines.append(f"| {r['task']} | {r['width']} | {float(r['mean_return']):.3f} | {cells} | "
                     f"{p50:.2f} | {p99:.2f} |")  # fmt: skip
    return "\n".join(lines)


def reach_table() -> str:
    lines = ["| n | re-plans | legal stimulations (median) | kept: quartiles | kept fraction: "
             "quartiles |", "|---:|---:|---:|---|---|"]  # fmt: skip
    for r in read_csv(HERE / "reach.csv"):
        kept = " / ".join(f"{float(r[f'kept_q{q}']):.0f}" for q in (25, 50, 75))
        fraction = " / ".join(f"{float(r[f'kept_fraction_q{q}']):.2f}" for q in (25, 50, 75))
        lines.append(f"| {r['n_neurons']} | {r['replans']} | {float(r['legal_q50']):.0f} | "
                     f"{kept} | {fraction} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    for split in ("validation", "test"):
        print(f"### {split}\n\n{returns_table(split)}\n")
    print(f"### decision times\n\n{times_table()}\n")
    print(f"### the real-time form's width (validation)\n\n{widths_table()}\n")
    print(f"### target paths: stimulations kept at a re-plan\n\n{reach_table()}")


if __name__ == "__main__":
    main()
