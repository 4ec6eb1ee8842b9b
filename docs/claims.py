"""The numbers the user pages state, each drawn from the committed result that is its
source: one current number per claim.

A claim is a page and a piece of its text in which each number is a placeholder naming
its source, ``{SOURCE:FORMAT}``. The check renders every claim from the committed CSVs
and fails where the page does not hold the rendered text (tests/test_docs.py); ``--write``
puts the rendered numbers into the pages (where a page holds the claim's text with other
numbers), so a redrawn CSV is copied to the pages by one command:

    python docs/claims.py            # lists each claim that disagrees with its source
    python docs/claims.py --write    # rewrites those numbers from the sources

Sources (paths under docs/results/suite/, the suite's committed results):

- ``suite/CONTROLLER/TASK/COLUMN``: a column of ``CONTROLLER.csv`` (``spikectl benchmark
  CONTROLLER --task all``) on TASK's row, e.g. ``suite/identify-and-plan/n32/mean_return``;
- ``suite2/CONTROLLER/TASK/COLUMN``: the same for suite v2 (``docs/results/suite-v2/``,
  ``spikectl benchmark CONTROLLER --suite 2 --task all``);
- ``summary/CONTROLLER``: the suite's summary, the mean over its ten tasks of the
  normalised column;
- ``trained/PRESET/paper/TASK/COLUMN``: over the seeds of ``trained/PRESET/paper``, the
  column on TASK's row of each seed's ``transfer.csv`` (trained on ``paper``);
- ``trained/PRESET/task/TASK/COLUMN``: the same from each seed trained on TASK itself
  (``trained/PRESET/TASK/seed=S/benchmark.csv``);
- ``final/FOLDER/COLUMN`` and ``best/FOLDER/COLUMN``: over the runs of
  ``docs/results/FOLDER/trials/seed=*``, the column of each run's last metrics row, or of
  its row of the highest validation return (the earliest of equal ones: where
  ``best_model.pt`` was taken); ``.../COLUMN/seed=S`` names one run;
- ``summary-trained/PRESET/paper``: over the seeds trained on ``paper``, each seed's mean
  normalised score on the ten tasks; ``summary-trained/PRESET/task``: seed S trained on
  each task (its ``paper`` run on ``paper``).

Formats: ``.3f`` (one value), ``pm`` (mean ± sd over seeds, three decimals; the sd with
NumPy's default, over the seeds as they are) and ``mean`` (the mean over seeds).

The old numbers of a claim belong in the dated research record (docs/research/), not in
a user page.
"""

from __future__ import annotations

import csv
import re
import sys
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
SUITE = DOCS / "results" / "suite"
SUITE2 = DOCS / "results" / "suite-v2"
TASKS = ("paper", "n16", "n32", "noise1", "noise2", "noise4", "hidden25", "stochastic",
         "heterogeneous", "background")  # fmt: skip
"""The suite's ten tasks (version 1), in its order."""
PLACEHOLDER = re.compile(r"\{([\w/.=-]+):([\w.]+)\}")


class Claim(NamedTuple):
    page: str
    """The page, relative to the repository root."""
    text: str
    """The page's text with each number as ``{SOURCE:FORMAT}``."""


@cache
def rows(path: Path) -> dict[str, dict[str, str]]:
    """A suite CSV's rows by task."""
    with open(path, newline="") as handle:
        return {row["task"]: row for row in csv.DictReader(handle)}


def seed_tables(preset: str, trained_on: str, task: str) -> list[dict[str, dict[str, str]]]:
    """Per seed, the rows by task of ``preset``'s runs trained on ``paper``
    (``transfer.csv``) or on ``task`` itself (``benchmark.csv``)."""
    if trained_on == "paper":
        files = sorted((SUITE / "trained" / preset / "paper").glob("seed=*/transfer.csv"))
    else:
        files = sorted((SUITE / "trained" / preset / task).glob("seed=*/benchmark.csv"))
    if not files:
        raise ValueError(f"no seeds of trained/{preset} trained on {trained_on} ({task})")
    return [rows(path) for path in files]


def specialist_scores(preset: str) -> list[float]:
    """Per seed S: the mean normalised score on the ten tasks of seed S trained on each
    task (``paper``'s own run on ``paper``)."""
    scores = []
    for path in sorted((SUITE / "trained" / preset / "paper").glob("seed=*/transfer.csv")):
        seed = path.parent.name
        own = {task: SUITE / "trained" / preset / task / seed / "benchmark.csv"
               for task in TASKS}  # fmt: skip
        table = {"paper": rows(path)["paper"]}
        table.update({task: rows(file)[task] for task, file in own.items() if task != "paper"})
        scores.append(np.mean([float(table[task]["normalised"]) for task in TASKS]))
    return scores


def values(source: str) -> list[float]:
    """The value (or, over seeds, the values) a source names."""
    kind, *parts = source.split("/")
    if kind == "suite":
        controller, task, column = parts
        return [float(rows(SUITE / f"{controller}.csv")[task][column])]
    if kind == "suite2":
        controller, task, column = parts
        return [float(rows(SUITE2 / f"{controller}.csv")[task][column])]
    if kind == "summary":
        (controller,) = parts
        table = rows(SUITE / f"{controller}.csv")
        return [float(np.mean([float(table[task]["normalised"]) for task in TASKS]))]
    if kind == "trained":
        preset, trained_on, task, column = parts
        return [float(table[task][column]) for table in seed_tables(preset, trained_on, task)]
    if kind in ("final", "best"):
        folder, column, *seed = parts
        runs = sorted((DOCS / "results" / folder / "trials").glob(seed[0] if seed else "seed=*"))
        if not runs:
            raise ValueError(f"docs/results/{folder} has no trials/seed=*")
        chosen = []
        for run in runs:
            with open(run / "metrics.csv", newline="") as handle:
                metrics = list(csv.DictReader(handle))
            scored = [row for row in metrics if row["val_return"] not in ("", "nan")]
            chosen.append(metrics[-1] if kind == "final"
                          else max(scored, key=lambda row: float(row["val_return"])))  # fmt: skip
        return [float(row[column]) for row in chosen]
    if kind == "summary-trained":
        preset, trained_on = parts
        if trained_on == "task":
            return specialist_scores(preset)
        tables = seed_tables(preset, "paper", "paper")
        return [float(np.mean([float(t[task]["normalised"]) for task in TASKS])) for t in tables]
    raise ValueError(f"unknown source {source!r}")


def render_value(source: str, form: str) -> str:
    numbers = values(source)
    if form == "pm":
        return f"{np.mean(numbers):.3f} ± {np.std(numbers):.3f}"
    if form == "mean":
        return f"{np.mean(numbers):.3f}"
    if len(numbers) != 1:
        raise ValueError(f"{source} has {len(numbers)} values: format it as pm")
    return format(numbers[0], form)


def render(claim: Claim) -> str:
    """The claim's text with each number drawn from its source."""
    return PLACEHOLDER.sub(lambda match: render_value(match[1], match[2]), claim.text)


def pattern(claim: Claim) -> re.Pattern[str]:
    """The claim's text with any numbers where its placeholders are."""
    parts = PLACEHOLDER.split(claim.text)
    literal = [re.escape(part) for part in parts[::3]]
    number = r"[−+-]?\d+(?:\.\d+)?(?: ± \d+\.\d+)?"
    return re.compile(number.join(literal))


def suite_row(task: str) -> str:
    """docs/benchmark.md's row of the training-free table for one task."""

    def cell(controller: str, extra: str = "") -> str:
        base = f"suite/{controller}/{task}"
        return (f"{{{base}/mean_return:.3f}} ± {{{base}/standard_error:.3f}} "
                f"({{{base}/normalised:.3f}}){extra}")  # fmt: skip

    oracle = (f"{{suite/oracle/{task}/mean_return:.3f}} ± "
              f"{{suite/oracle/{task}/standard_error:.3f}} (1)")  # fmt: skip
    random = cell("random", f", sd {{suite/random/{task}/sd_over_seeds:.3f}}")
    return (f"| `{task}` | {cell('do-nothing')} | {random} | {cell('identify-and-plan')} "
            f"| {oracle} |")  # fmt: skip


def suite2_row(task: str) -> str:
    """docs/benchmark.md's suite v2 row of ``task``."""

    def cell(controller: str, standard_error: bool) -> str:
        source = f"suite2/{controller}/{task}"
        error = f" ± {{{source}/standard_error:.3f}}" if standard_error else ""
        return f"{{{source}/mean_return:.3f}}{error} ({{{source}/normalised:.3f}})"

    return (f"| `{task}` | {{suite2/do-nothing/{task}/mean_return:.3f}} (0) | "
            f"{cell('random', False)} | {cell('identify-and-plan', True)} | "
            f"{{suite2/oracle/{task}/mean_return:.3f}} ± "
            f"{{suite2/oracle/{task}/standard_error:.3f}} (1) |")  # fmt: skip


def learned_row(task: str) -> str:
    """docs/benchmark.md's row of the learned table for one task."""
    on_task = "paper" if task == "paper" else "task"  # paper's own runs are its transfer rows
    cells = [f"{{suite/identify-and-plan/{task}/mean_return:.3f}}",
             f"{{trained/quick/paper/{task}/mean_return:pm}}",
             f"{{trained/guided-upr24/paper/{task}/mean_return:pm}}",
             f"{{trained/guided-upr24/{on_task}/{task}/mean_return:pm}}"]  # fmt: skip
    return f"| `{task}` | " + " | ".join(cells) + " |"


def claims() -> Iterator[Claim]:
    """Every claim of the user pages."""
    benchmark = "docs/benchmark.md"
    for task in TASKS:
        yield Claim(benchmark, suite_row(task))
        yield Claim(benchmark, learned_row(task))
    for task in ("paper", "latency1", "latency2", "spikes-only", "chr2", "rig"):
        yield Claim(benchmark, suite2_row(task))
    yield Claim(benchmark, "| **mean normalised** | {summary/do-nothing:.3f} | "
                "{summary/random:.3f} | **{summary/identify-and-plan:.3f}** | "
                "{summary/oracle:.3f} |")  # fmt: skip
    for controller, label in (("oracle", "oracle planner (knows the network)"),
                              ("identify-and-plan", "identify-and-plan"),
                              ("identify-and-plan-realtime", "identify-and-plan's real-time form"),
                              ("random", "random (10 seeds)"),
                              ("do-nothing", "do nothing")):  # fmt: skip
        yield Claim(benchmark, f"| {label} | `spikectl benchmark {controller} --task all` "
                    f"| none | {{summary/{controller}:.3f}} |")  # fmt: skip
    yield Claim(benchmark, "every task | ten runs, about 200 core-minutes | "
                "{summary-trained/guided-upr24/task:pm} |")  # fmt: skip
    yield Claim(benchmark, "| `train.sh paper S guided guided-upr24` | about 15 core-minutes "
                "| {summary-trained/guided-upr24/paper:pm} |")  # fmt: skip
    yield Claim(benchmark, "| `train.sh paper S` | about 15 core-minutes "
                "| {summary-trained/quick/paper:pm} |")  # fmt: skip
    yield Claim(benchmark, "identify-and-plan\n  scores "
                "{suite/identify-and-plan/paper/normalised:.3f} of the way")  # fmt: skip
    yield Claim(benchmark, "The normalised score is "
                "{suite/identify-and-plan/paper/normalised:.3f} at n = 8, "
                "{suite/identify-and-plan/n16/normalised:.3f} at\n  n = 16 and "
                "{suite/identify-and-plan/n32/normalised:.3f} at n = 32")  # fmt: skip
    yield Claim(benchmark, "The quick TDRQN, at {trained/quick/paper/paper/normalised:mean} on "
                "`paper`")  # fmt: skip
    yield Claim(benchmark, "scores {trained/guided-upr24/task/stochastic/mean_return:pm} "
                "(seeds at")  # fmt: skip
    yield Claim(benchmark, "against identify-and-plan's "
                "{suite/identify-and-plan/stochastic/mean_return:.3f}; it was")  # fmt: skip
    yield Claim(benchmark, "Identify-and-plan reaches {suite/identify-and-plan/stochastic/"
                "mean_return:.3f} raw")  # fmt: skip

    baselines = "docs/baselines.md"
    yield Claim(baselines, "| TDRQN `guided` (the main job; 3 seeds, mean ± sd over seeds) | "
                "{trained/guided-upr24/paper/paper/mean_return:pm} | 264 k steps |")  # fmt: skip
    yield Claim(baselines, "| TDRQN `quick` (3 seeds) | "
                "{trained/quick/paper/paper/mean_return:pm} | 264 k steps |")  # fmt: skip
    yield Claim(baselines, "([below](#identify-and-plan-under-the-tasks-observation-model)) "
                "and scores {suite/identify-and-plan/noise1/mean_return:.3f},\n"
                "{suite/identify-and-plan/noise2/mean_return:.3f} and "
                "{suite/identify-and-plan/noise4/mean_return:.3f} at σ = 1, 2 and 4 mV")
    normalised = {task: f"{{suite/identify-and-plan/{task}/normalised:.3f}}" for task in TASKS}
    tails = {  # the end of each row of the named controller's table (its configuration)
        "paper": "| `paper` | `paper` | the constructor's default |",
        "hidden25": "(the `\"relays\"` estimator) |",
        "heterogeneous": "known synapses planned at their strength |",
        "background": "(`known_sd`; 0.25 by default) |",
        "stochastic": "where the plan misses the next wanted spike |",
        "n16": "drawn from its estimate (QMDP) |",
        "n32": "(the `\"particles\"` estimator) |",
    }
    for task, tail in tails.items():
        yield Claim(baselines, f"{tail} {normalised[task]} |\n")
    noise = ", ".join(normalised[task] for task in ("noise1", "noise2", "noise4"))
    yield Claim(baselines, f"within the read margin of the threshold | {noise} |\n")
    yield Claim(baselines, "Identify-and-plan does not reach 0.90 at n = 8 "
                "({suite/identify-and-plan/paper/mean_return:.3f} on the test networks) "
                "nor at\n  n = 32 ({suite/identify-and-plan/n32/mean_return:.3f}, "
                "the named controller)")  # fmt: skip
    yield Claim(baselines, "the named controller of `spikectl benchmark` scores\n"
                "{suite/identify-and-plan/n32/mean_return:.3f} on the suite's `n32` test "
                "networks")  # fmt: skip

    readme = "README.md"  # checked here; edited by hand, as its own commit says
    yield Claim(readme, "| `spikectl train guided` | 0.82 | 0.80–0.82 "
                "({final/guided-ntrain1000/test_return:pm}) | 0.83–0.84 |")  # fmt: skip
    yield Claim(readme, "| identify-and-plan, no training | | "
                "{suite/identify-and-plan/paper/mean_return:.3f} | |")  # fmt: skip

    training = "docs/training.md"
    yield Claim(training, "| identify-and-plan | `spikectl benchmark identify-and-plan --task "
                "paper n16 n32` | {suite/identify-and-plan/paper/mean_return:.3f} | "
                "{suite/identify-and-plan/n16/mean_return:.3f} | "
                "{suite/identify-and-plan/n32/mean_return:.3f} |")  # fmt: skip
    yield Claim(training, "| the main job | `spikectl train guided` (`--task n16`, `--task n32`) "
                "| {best/guided-ntrain1000/test_return:mean} "
                "| {trained/guided-upr24/task/n16/mean_return:mean} "
                "| {trained/guided-upr24/task/n32/mean_return:mean} |")  # fmt: skip
    yield Claim("docs/reproduction.md", "| identify-and-plan (no training) | – | – | – | "
                "{suite/identify-and-plan/paper/mean_return:.3f} |")  # fmt: skip
    yield Claim("docs/realtime.md", "identical returns (test "
                "{best/quick-this-machine/test_return/seed=0:.3f}, validation "
                "{best/quick-this-machine/val_return/seed=0:.3f})")  # fmt: skip
    yield Claim("docs/getting-started.md", "identify-and-plan              "
                "{suite/identify-and-plan/paper/mean_return:.3f}")  # fmt: skip
    yield Claim("docs/getting-started.md", "oracle                         "
                "{suite/oracle/paper/mean_return:.3f}")  # fmt: skip


def disagreements(root: Path = ROOT) -> list[str]:
    """Each claim whose page does not hold its rendered text, or holds its text with
    other numbers as well (a stale copy), in one line."""
    found = []
    for claim in claims():
        text, expected = (root / claim.page).read_text(), render(claim)
        written = [match[0] for match in pattern(claim).finditer(text)]
        if not written:
            found.append(f"{claim.page}: {expected!r} is not on the page")
        for stale in sorted({line for line in written if line != expected}):
            found.append(f"{claim.page}: says {stale!r}; its source says {expected!r}")
    return found


def write(root: Path = ROOT) -> int:
    """Rewrites each claim's numbers on its page from its source; returns how many
    places changed."""
    changed = 0
    for claim in claims():
        page = root / claim.page
        text, expected = page.read_text(), render(claim)
        new = pattern(claim).sub(lambda _, rendered=expected: rendered, text)
        if new != text:
            changed += sum(m[0] != expected for m in pattern(claim).finditer(text))
            page.write_text(new)
    return changed


if __name__ == "__main__":
    if sys.argv[1:] == ["--write"]:
        print(f"{write()} claims rewritten")
    wrong = disagreements()
    print("\n".join(wrong) or "every claim agrees with its source")
    sys.exit(1 if wrong else 0)
