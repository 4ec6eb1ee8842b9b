"""Return against decision time at n = 8, 16, 32 and 64 (issue 61, item 3): the rows the
committed results lack, measured with the public API.

    python lab/results/realtime-tradeoff/measure.py n64 OUT_DIR [--belief belief.pt]
    python lab/results/realtime-tradeoff/measure.py fast OUT_DIR    # after n64: its references
    python lab/results/realtime-tradeoff/measure.py times OUT_DIR [--belief belief.pt]

``n64``: doing nothing, the random controller, the oracle and (where ``--belief`` names
its weights) the amortised controller on :func:`n64_contexts`, which no suite task has.
``fast``: the named identify-and-plan's fast form (``named_composition(..., fast=True)``:
no QMDP, no particles; what the guided learner's teacher plays) on the test sets of
suite v1's ``paper``, ``n16`` and ``n32`` and on :func:`n64_contexts`, scored under the
suite's protocol, each network's return kept (``fast-per-network.csv``).
``times``: every controller of the table timed in one run, so that their times compare:
each decision's CPU time on its thread (:func:`spikectl.envs.realtime.decision_times`),
one environment, the set's first :data:`TIMED_EPISODES` networks after a warm-up
episode, as ``spikectl benchmark`` times a row. The TDRQN is the main job's architecture
(the committed ``guided`` config) compiled as the rig runs it, at fresh weights built
for each size: a forward pass costs the same whatever the weights.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.records import write_csv
from spikectl import NeuronControlEnv, load_controller, make_splits
from spikectl.envs.realtime import decision_times
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import IdentifyAndPlan, named_composition
from spikectl.training.config import Experiment

ROOT = Path(__file__).resolve().parents[3]
MAIN_JOB_CONFIG = ROOT / "docs" / "results" / "suite" / "trained" / "guided-upr24" / "paper"
TASKS = ("paper", "n16", "n32")
TIMED_EPISODES = 10
N64 = 64
FIELDS = ("n_neurons", "task", "controller", "mean_return", "standard_error", "normalised",
          "cpu_seconds")  # fmt: skip


def n64_contexts():
    """The test set at n = 64: suite v1's rule at that size (``make_splits(100, 100, 64,
    seed=0, n_val=100)``), which no suite task has."""
    return make_splits(100, 100, N64, seed=0, n_val=100)[1]


def test_set(task: str):
    """(contexts, extensions) of a suite v1 task's test set, or of the n = 64 set."""
    if task == "n64":
        return n64_contexts(), None
    return suite.load_split(task, "test"), suite.task(task).extensions


def timed(contexts, extensions, controller) -> tuple[float, float]:
    """(p50, p99) of the controller's decision CPU time in ms (after a warm-up episode)."""
    env = NeuronControlEnv(contexts=contexts, extensions=extensions)
    decision_times(env, controller, [0])
    times = decision_times(env, controller, range(TIMED_EPISODES)) * 1e3
    return float(np.median(times)), float(np.percentile(times, 99))


def played(contexts, extensions, controller) -> tuple[np.ndarray, float]:
    started = time.process_time()
    episodes = evaluate_policy(contexts, controller, extensions=extensions,
                               seed=suite.suite_version(1).env_seed)  # fmt: skip
    return np.asarray(episodes.returns), time.process_time() - started


def row(n: int, task: str, name: str, returns, cpu: float, references) -> dict:
    nothing, oracle = references
    mean = float(np.mean(returns))
    return dict(zip(FIELDS, [
        n, task, name, f"{mean:.6f}", f"{suite.standard_error(returns):.6f}",
        f"{suite.normalise(mean, nothing, oracle):.6f}", f"{cpu:.3f}",
    ], strict=True))  # fmt: skip


def fast(out: Path) -> None:
    rows, per_network = [], []
    references = json.loads((out / "n64-references.json").read_text())
    for task in (*TASKS, "n64"):
        contexts, extensions = test_set(task)
        composition = named_composition(extensions, contexts.n_observed, fast=True)
        returns, cpu = played(contexts, extensions,
                              IdentifyAndPlan(composition=composition, extensions=extensions))
        if task == "n64":
            refs = (references["do-nothing"], references["oracle"])
        else:
            refs = tuple(score.mean_return for score in suite.reference_scores(task, "test"))
        rows.append(row(contexts.n_neurons, task, f"identify-and-plan {composition.name}",
                        returns, cpu, refs))  # fmt: skip
        per_network += [{"task": task, "context": i, "return": repr(float(value))}
                        for i, value in enumerate(returns)]  # fmt: skip
        print(rows[-1], flush=True)
    write_csv(out / "fast.csv", rows)
    write_csv(out / "fast-per-network.csv", per_network)


def compiled_tdrqn(n_observed: int):
    """The main job's network (its committed config) for ``n_observed`` neurons at fresh
    weights, compiled."""
    import torch

    from spikectl.agents import make_agent
    from spikectl.agents.compiled import CompiledPolicy

    config = Experiment.from_dict(json.loads((MAIN_JOB_CONFIG / "seed=0" / "config.json")
                                             .read_text()))  # fmt: skip
    torch.set_num_threads(1)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        network = make_agent(config.agent.arch, n_observed, config.env.episode_length,
                             config.agent.sizes, params=config.env.params)  # fmt: skip
    return CompiledPolicy.from_network(network)


def times(out: Path, belief: Path | None) -> None:
    rows = []
    for task in (*TASKS, "n64"):
        contexts, extensions = test_set(task)
        env = NeuronControlEnv(contexts=contexts, extensions=extensions)
        fast_form = named_composition(extensions, contexts.n_observed, fast=True)
        controllers = {name: load_controller(name, env=env)
                       for name in ("do-nothing", "random", "oracle")}  # fmt: skip
        if task != "n64":  # the named form at 64: QMDP over particles, seconds a decision
            controllers["identify-and-plan (named)"] = load_controller("identify-and-plan",
                                                                       env=env)  # fmt: skip
        controllers["identify-and-plan, fast form"] = IdentifyAndPlan(
            composition=fast_form, extensions=extensions)
        controllers["TDRQN, compiled"] = compiled_tdrqn(contexts.n_observed)
        if belief is not None:
            controllers["amortised controller"] = load_controller(belief, env=env)
        for name, controller in controllers.items():
            p50, p99 = timed(contexts, extensions, controller)
            rows.append({"n_neurons": contexts.n_neurons, "task": task, "controller": name,
                         "decision_p50_ms": f"{p50:.4f}", "decision_p99_ms": f"{p99:.4f}",
                         "load_average_1min": f"{os.getloadavg()[0]:.2f}"})  # fmt: skip
            print(rows[-1], flush=True)
    write_csv(out / "times.csv", rows)


def n64(out: Path, belief: Path | None) -> None:
    contexts, extensions = test_set("n64")
    env = NeuronControlEnv(contexts=contexts)
    names = ["do-nothing", "oracle", "random"] + ([str(belief)] if belief else [])
    results = {}
    for name in names:
        returns, cpu = played(contexts, None, load_controller(name, env=env))
        results[name] = (returns, cpu)
        print(name, float(np.mean(returns)), flush=True)
    references = {name: float(np.mean(results[name][0])) for name in ("do-nothing", "oracle")}
    (out / "n64-references.json").write_text(json.dumps(references, indent=1) + "\n")
    write_csv(out / "n64.csv", [
        row(N64, "n64", "amortised controller" if name == str(belief) else name, returns, cpu,
            (references["do-nothing"], references["oracle"]))
        for name, (returns, cpu) in results.items()
    ])  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("n64", "fast", "times"))
    parser.add_argument("out", type=Path)
    parser.add_argument("--belief", type=Path, help="the amortised belief's weights (.pt)")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    args.out.mkdir(parents=True, exist_ok=True)
    {"n64": lambda: n64(args.out, args.belief), "fast": lambda: fast(args.out),
     "times": lambda: times(args.out, args.belief)}[args.what]()  # fmt: skip


if __name__ == "__main__":
    main()
