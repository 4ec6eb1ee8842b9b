"""Identify-and-plan's fast form against its real-time form and against the same with
its beam cut to the target's ancestors (issue 61): their returns on a split of suite v1's
tasks, and their decision times on one core.

    python lab/results/realtime-iap/measure.py play validation OUT_DIR [--tasks paper n16]
                                                    [--forms fast realtime]
    python lab/results/realtime-iap/measure.py play test OUT_DIR
    python lab/results/realtime-iap/measure.py times OUT_DIR
    python lab/results/realtime-iap/measure.py reach OUT_DIR
    python lab/results/realtime-iap/measure.py widths OUT_DIR

``play``: the fast form (``named_composition(..., fast=True)``, what the guided learner's
teacher plays), the real-time form (``realtime=True``: the same at a narrower beam,
``identify-and-plan-realtime``) and the fast form with the decision part
:class:`lab.planners.TargetPathsOnly` (the beam expanding only the stimulations that can
reach the target; ``target-paths``) on each task's split, scored under the suite's
protocol; each network's return (``SPLIT-per-network.csv``) and each row's CPU seconds
(``SPLIT.csv``), the rows of forms not played kept. The test split adds the n = 64 set
of lab/results/realtime-tradeoff (``n64_contexts``).
``times``: the forms on the test sets of ``paper``, ``n16``, ``n32`` and n = 64, each
decision's CPU time on its thread (:func:`spikectl.envs.realtime.decision_times`), the
set's first :data:`TIMED_EPISODES` networks after a warm-up episode, the forms
alternating over :data:`ROUNDS` rounds so that all meet the same load
(:func:`timed_rounds`); every decision kept (``times-per-decision.csv``), p50 and p99
per form and size (``times.csv``).
``widths``: the choice of the real-time form's beam width: the fast form at each of
:data:`WIDTHS` on the validation sets of :data:`WIDTH_TASKS`, each network's return
(``widths-per-network.csv``), and each width's decision times on the same networks, the
widths alternating over :data:`ROUNDS` rounds (``widths.csv``).
``reach``: at each re-plan of the cut form on the same networks, how many stimulations
the beam keeps of the legal ones (``reach.csv``: their quartiles per size).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners import TargetPathsOnly
from lab.records import write_csv
from lab.scripts import load_script
from spikectl import NeuronControlEnv
from spikectl.envs.realtime import decision_times
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import IdentifyAndPlan, named_composition

HERE = Path(__file__).resolve().parent
TIMED_TASKS = ("paper", "n16", "n32", "n64")
TIMED_EPISODES = 10
ROUNDS = 2
WIDTHS = (32, 24, 16, 12, 8)
WIDTH_TASKS = ("paper", "n16", "n32")
FORMS = ("fast", "realtime", "target-paths")
"""The fast form, the real-time form, and the fast form with
:class:`~lab.planners.TargetPathsOnly`."""


def _tradeoff():
    """lab/results/realtime-tradeoff/measure.py (its n = 64 set and test sets)."""
    return load_script("realtime-tradeoff", "measure")


def split_set(task: str, split: str):
    """(contexts, extensions) of a suite v1 task's split, or of the n = 64 test set."""
    if task == "n64":
        return _tradeoff().test_set("n64")
    return suite.load_split(task, split), suite.task(task).extensions


def controller(form: str, contexts, extensions) -> IdentifyAndPlan:
    composition = named_composition(extensions, contexts.n_observed, fast=True,
                                     realtime=form == "realtime")  # fmt: skip
    if form == "target-paths":
        decision = TargetPathsOnly(**vars(composition.decision))
        composition = composition.but(f"{composition.name}-target-paths", decision=decision)
    return IdentifyAndPlan(composition=composition, extensions=extensions)


def _kept(path: Path, played: set[tuple[str, str]]) -> list[dict]:
    """The rows of ``path`` (if any) whose (task, form) is not in ``played``."""
    if not path.exists():
        return []
    with open(path, newline="") as handle:
        return [r for r in csv.DictReader(handle) if (r["task"], r["form"]) not in played]


def play(split: str, out: Path, tasks: list[str], forms: list[str]) -> None:
    rows, per_network = [], []
    for task in tasks:
        contexts, extensions = split_set(task, split)
        for form in forms:
            played = controller(form, contexts, extensions)
            started = time.process_time()
            episodes = evaluate_policy(contexts, played, extensions=extensions,
                                       seed=suite.suite_version(1).env_seed)  # fmt: skip
            cpu = time.process_time() - started
            returns = np.asarray(episodes.returns)
            rows.append({"task": task, "split": split, "form": form,
                         "composition": played.composition.name,
                         "mean_return": f"{returns.mean():.6f}",
                         "standard_error": f"{suite.standard_error(returns):.6f}",
                         "cpu_seconds": f"{cpu:.3f}"})  # fmt: skip
            per_network += [{"task": task, "form": form, "context": i, "return": repr(float(r))}
                            for i, r in enumerate(returns)]  # fmt: skip
            print(rows[-1], flush=True)
    replaced = {(task, form) for task in tasks for form in forms}
    for name, new in ((f"{split}.csv", rows), (f"{split}-per-network.csv", per_network)):
        merged = _kept(out / name, replaced) + new
        order = list(dict.fromkeys(r["task"] for r in merged))
        # Stable: each form's networks stay in order.
        merged.sort(key=lambda r: (order.index(r["task"]), FORMS.index(r["form"])))
        write_csv(out / name, merged)


def timed_rounds(env, controllers: dict) -> dict:
    """Each controller's decision CPU times in ms, one array per round: after a warm-up
    episode each (compilation, caches), the controllers alternate over :data:`ROUNDS`
    rounds of the set's first :data:`TIMED_EPISODES` networks, so that all meet the same
    load."""
    for played in controllers.values():
        decision_times(env, played, [0])
    rounds = {key: [] for key in controllers}
    for _ in range(ROUNDS):
        for key, played in controllers.items():
            rounds[key].append(decision_times(env, played, range(TIMED_EPISODES)) * 1e3)
    return rounds


def times(out: Path, forms: list[str]) -> None:
    decisions = []
    for task in TIMED_TASKS:
        contexts, extensions = split_set(task, "test")
        env = NeuronControlEnv(contexts=contexts, extensions=extensions)
        rounds = timed_rounds(env, {form: controller(form, contexts, extensions)
                                    for form in forms})  # fmt: skip
        for round_ in range(ROUNDS):
            for form in forms:
                decisions += [{"task": task, "n_neurons": contexts.n_neurons, "form": form,
                               "round": round_, "decision": i, "ms": f"{value:.5f}"}
                              for i, value in enumerate(rounds[form][round_])]  # fmt: skip
        print(task, flush=True)
    write_csv(out / "times-per-decision.csv", decisions)
    rows = []
    for task in TIMED_TASKS:
        for form in forms:
            mine = [r for r in decisions if r["task"] == task and r["form"] == form]
            ms = np.array([float(r["ms"]) for r in mine])
            rows.append({"task": task, "n_neurons": mine[0]["n_neurons"], "form": form,
                         "decisions": ms.size, "decision_p50_ms": f"{np.median(ms):.4f}",
                         "decision_p99_ms": f"{np.percentile(ms, 99):.4f}",
                         "decision_max_ms": f"{ms.max():.4f}",
                         "load_average_1min": f"{os.getloadavg()[0]:.2f}"})  # fmt: skip
            print(rows[-1], flush=True)
    write_csv(out / "times.csv", rows)


def widths(out: Path) -> None:
    rows, per_network = [], []
    for task in WIDTH_TASKS:
        contexts, extensions = split_set(task, "validation")
        fast = named_composition(extensions, contexts.n_observed, fast=True)
        controllers = {width: IdentifyAndPlan(composition=fast.with_width(width),
                                              extensions=extensions)
                       for width in WIDTHS}  # fmt: skip
        rounds = timed_rounds(NeuronControlEnv(contexts=contexts, extensions=extensions),
                              controllers)  # fmt: skip
        for width, played in controllers.items():
            episodes = evaluate_policy(contexts, played, extensions=extensions,
                                       seed=suite.suite_version(1).env_seed)  # fmt: skip
            returns = np.asarray(episodes.returns)
            ms = np.concatenate(rounds[width])
            rows.append({"task": task, "width": width, "mean_return": f"{returns.mean():.6f}",
                         "decision_p50_ms": f"{np.median(ms):.4f}",
                         "decision_p99_ms": f"{np.percentile(ms, 99):.4f}"})  # fmt: skip
            per_network += [{"task": task, "width": width, "context": i,
                             "return": repr(float(r))} for i, r in enumerate(returns)]  # fmt: skip
            print(rows[-1], flush=True)
    write_csv(out / "widths.csv", rows)
    write_csv(out / "widths-per-network.csv", per_network)


REPLANS: list[tuple[int, int]] = []
"""(kept, legal) stimulations at each re-plan of :class:`_Counting`."""


class _Counting(TargetPathsOnly):
    """TargetPathsOnly that records (kept, legal) stimulations at each re-plan."""

    def planning_model(self, policy, weights, situation):
        model = super().planning_model(policy, weights, situation)
        REPLANS.append((model.actions.size - 1, situation.actions.size - 1))
        return model


def reach(out: Path) -> None:
    rows = []
    for task in TIMED_TASKS:
        contexts, extensions = split_set(task, "test")
        composition = named_composition(extensions, contexts.n_observed, fast=True)
        composition = composition.but("counting", decision=_Counting(**vars(composition.decision)))
        REPLANS.clear()
        played = IdentifyAndPlan(composition=composition, extensions=extensions)
        decision_times(NeuronControlEnv(contexts=contexts, extensions=extensions), played,
                       range(TIMED_EPISODES))  # fmt: skip
        kept, legal = np.array(REPLANS).T
        row = {"task": task, "n_neurons": contexts.n_neurons, "replans": kept.size}
        for name, values in (("kept", kept), ("legal", legal), ("kept_fraction", kept / legal)):
            row.update({f"{name}_q{q}": f"{np.percentile(values, q):.3f}" for q in (25, 50, 75)})
        rows.append(row)
        print(row, flush=True)
    write_csv(out / "reach.csv", rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("play", "times", "reach", "widths"))
    parser.add_argument("split", nargs="?", choices=("validation", "test"))
    parser.add_argument("out", type=Path)
    parser.add_argument("--tasks", nargs="*", help="suite v1 tasks (default: all)")
    parser.add_argument("--forms", nargs="*", choices=FORMS, default=list(FORMS),
                        help="the forms to play or time (default: all)")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.what != "play":
        {"times": lambda: times(args.out, args.forms), "reach": lambda: reach(args.out),
         "widths": lambda: widths(args.out)}[args.what]()  # fmt: skip
        return
    if args.split is None:
        parser.error("play needs a split (validation or test)")
    tasks = args.tasks or list(suite.suite_version(1).tasks)
    if args.split == "test" and not args.tasks:
        tasks.append("n64")
    play(args.split, args.out, tasks, args.forms)


if __name__ == "__main__":
    main()
