"""The named identify-and-plan on suite v2's ``rig`` TEST set, played once after the
choice on the validation set: the rows ``spikectl benchmark identify-and-plan --suite 2
--task rig --out ... --per-network ...`` writes, normalised against the do-nothing and
oracle rows already in docs/results/suite-v2 (the CLI would plan the oracle's 1 000
episodes again, ~1 200 CPU s, for the same numbers), and the paired differences against
the per-network returns there (doing nothing and the oracle on ``rig``, identify-and-plan
on ``spikes-only`` and ``chr2``).

    python lab/results/iap-rig/play_test_row.py OUT_DIR

or in parts, one a core, then the rows from them (the same returns, network by network:
:func:`lab.planners.named_row.play_named_part`):

    python lab/results/iap-rig/play_test_row.py OUT_DIR 0:500      # OUT_DIR/part-0-500.csv
    python lab/results/iap-rig/play_test_row.py OUT_DIR 500:1000
    python lab/results/iap-rig/play_test_row.py OUT_DIR --merge
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.named_row import play_named, play_named_part, write_rows
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells

TASK, SPLIT, VERSION = "rig", "test", 2
OLD = Path("docs/results/suite-v2")
FIRST_ROW = Path("docs/results/iap-rig/test/identify-and-plan-rig-per-network.csv")
COLUMNS = ["suite_version", "task", "split", "controller", "model", "seeds", "mean_return",
           "standard_error", "sd_over_seeds", "normalised", "do_nothing", "oracle",
           "cpu_seconds", "contexts", "trained_on", "composition"]  # fmt: skip


def reference(controller: str) -> float:
    with open(OLD / f"{controller}.csv") as handle:
        return float(next(r for r in csv.DictReader(handle) if r["task"] == TASK)["mean_return"])


def per_network(controller: str, task: str) -> np.ndarray:
    with open(OLD / f"{controller}-per-network.csv") as handle:
        rows = [r for r in csv.DictReader(handle) if r["task"] == task]
    return np.array([float(r["return"]) for r in sorted(rows, key=lambda r: int(r["context"]))])


def play_part(out: Path, networks: range) -> None:
    """Networks ``networks`` of the test set: ``out/part-FIRST-END.csv`` (``context,
    return,cpu_s,composition``; the part's CPU seconds on its first row)."""
    out.mkdir(parents=True, exist_ok=True)
    returns, cpu, composition = play_named_part(TASK, networks, SPLIT)
    with open(out / f"part-{networks.start}-{networks.stop}.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["context", "return", "cpu_s", "composition"])
        cells = [f"{cpu:.3f}"] + [""] * (len(returns) - 1)
        rows = zip(networks, returns, cells, strict=True)
        writer.writerows([i, repr(float(value)), cell, composition] for i, value, cell in rows)
    print(f"networks {networks.start}-{networks.stop - 1}: {returns.mean():.4f}, {cpu:.1f} CPU s")


def merged(out: Path) -> tuple[suite.Score, str, int]:
    """The whole set's score from the parts in ``out`` (every network once)."""
    rows, cpu, names = {}, 0.0, set()
    for part in sorted(out.glob("part-*.csv")):
        with open(part) as handle:
            for row in csv.DictReader(handle):
                if int(row["context"]) in rows:
                    raise ValueError(f"{part}: network {row['context']} is in two parts")
                rows[int(row["context"])] = float(row["return"])
                cpu += float(row["cpu_s"] or 0.0)
                names.add(row["composition"])
    size = len(suite.load_split(TASK, SPLIT, VERSION))
    if sorted(rows) != list(range(size)) or len(names) != 1:
        raise ValueError(f"the parts in {out} hold {len(rows)} of {size} networks, "
                         f"compositions {sorted(names)}")  # fmt: skip
    returns = np.array([rows[i] for i in range(size)])
    return suite.Score(TASK, SPLIT, returns, returns.mean()[None], cpu), names.pop(), size


def main(out: Path, parts: bool = False) -> None:
    out.mkdir(parents=True, exist_ok=True)
    result, composition, n_networks = merged(out) if parts else play_named(TASK, SPLIT, VERSION)
    nothing, oracle = reference("do-nothing"), reference("oracle")
    row = dict(zip(COLUMNS, [
        VERSION, TASK, SPLIT, "identify-and-plan", "", 1, f"{result.mean_return:.6f}",
        f"{result.standard_error:.6f}", "",
        f"{suite.normalise(result.mean_return, nothing, oracle):.6f}", f"{nothing:.6f}",
        f"{oracle:.6f}", f"{result.cpu_seconds:.3f}", n_networks, "", composition,
    ], strict=True))  # fmt: skip
    write_rows(out, TASK, row, result, composition, VERSION)
    print(f"rig test: {result.mean_return:.4f} ± {result.standard_error:.4f} (normalised "
          f"{row['normalised']}); {result.cpu_seconds:.1f} CPU s; {composition}")  # fmt: skip
    for controller, task in (("do-nothing", "rig"), ("oracle", "rig"),
                             ("identify-and-plan", "spikes-only"),
                             ("identify-and-plan", "chr2")):  # fmt: skip
        other = per_network(controller, task)
        print(f"− {controller} on {task}, network by network: "
              f"{paired_difference_cells(result.returns - other)}")  # fmt: skip
    if parts:  # against the first rig row (planned on the estimate alone), kept in test/
        with open(FIRST_ROW) as handle:
            first = np.array([float(r["return"]) for r in csv.DictReader(handle)])
        print(f"− identify-and-plan's first rig row, network by network: "
              f"{paired_difference_cells(result.returns - first)}")  # fmt: skip


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[2] != "--merge":
        first, _, last = sys.argv[2].partition(":")
        play_part(Path(sys.argv[1]), range(int(first), int(last)))
    else:
        main(Path(sys.argv[1]), parts=sys.argv[2:] == ["--merge"])
