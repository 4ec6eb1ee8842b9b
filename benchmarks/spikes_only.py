"""Spikes-only sensing (docs/extensions.md, "Spikes-only sensing"): returns on the paper
task's 100 unseen test networks with the potentials observed (the paper) and with spikes
only, and, with --cleo, the agreement of spikectl's spikes-only environment with Cleo's
``spikes-only`` setting.

Rows: doing nothing, a seeded random controller, the oracle (which knows the network and
plans open loop), and identify-and-plan (its named composition for each sensing: the
``spikes`` one identifies from spikes alone, spikectl/planning/spike_filter.py). Each
value is the mean ± its standard error over the networks. With --cleo (run in the Cleo
virtualenv) every episode of the oracle and of random controllers seeded 0 ..
--random-seeds - 1 is played in both and the observations, actions, target spikes and
returns compared; the differences are counted. With --decisions N, identify-and-plan's
decision times (wall-clock around each ``act``) and CPU seconds on the first N networks
of suite v2's ``spikes-only`` test set.
Seconds without --cleo, minutes with it:

    python benchmarks/spikes_only.py [--cleo] [--decisions 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spikectl.envs.controller import DoNothing, RandomLegal, play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split
from spikectl.neuron.extensions import Extensions
from spikectl.planning.named import named_composition
from spikectl.planning.oracle import OraclePlanner
from spikectl.planning.policy import IdentifyAndPlan

SPIKES = Extensions(sensing="spikes")


def mean_and_error(returns: np.ndarray) -> str:
    return f"{returns.mean():.4f} ± {returns.std(ddof=1) / np.sqrt(returns.size):.4f}"


def scores(contexts) -> None:
    """The table: each controller's mean return with potentials and with spikes only."""
    n = contexts[0].n_neurons
    print("| controller | potentials (paper) | spikes only | CPU s (spikes only) |")
    print("|---|---:|---:|---:|")
    for name, make in (
        ("do nothing", DoNothing),
        ("random (seed 0)", lambda: RandomLegal(seed=0)),
        ("oracle", lambda: OraclePlanner(contexts, contexts.params)),
    ):
        paper = evaluate_policy(contexts, make(), seed=0).returns
        started = time.process_time()
        spikes = evaluate_policy(contexts, make(), extensions=SPIKES, seed=0).returns
        seconds = time.process_time() - started
        same = "identical per network" if np.array_equal(paper, spikes) else "differ"
        print(f"| {name} | {mean_and_error(paper)} | {mean_and_error(spikes)} ({same}) "
              f"| {seconds:.1f} |")  # fmt: skip
    planner = IdentifyAndPlan(contexts.params, named_composition(Extensions(), n))
    paper = evaluate_policy(contexts, planner, seed=0).returns
    planner = IdentifyAndPlan(contexts.params, named_composition(SPIKES, n), extensions=SPIKES)
    started = time.process_time()
    spikes = evaluate_policy(contexts, planner, extensions=SPIKES, seed=0).returns
    seconds = time.process_time() - started
    difference = spikes - paper
    print(f"| identify-and-plan | {mean_and_error(paper)} | {mean_and_error(spikes)} "
          f"(paired difference {mean_and_error(difference)}) | {seconds:.1f} |")  # fmt: skip


class Recording:
    """A controller that plays another and keeps every observation it was shown."""

    def __init__(self, controller) -> None:
        self.controller, self.seen = controller, []

    def reset(self) -> None:
        self.seen = []
        self.controller.reset()

    def act(self, observation, info) -> int:
        self.seen.append(observation)
        return self.controller.act(observation, info)


def same_observations(a: list[dict], b: list[dict]) -> bool:
    return len(a) == len(b) and all(
        x.keys() == y.keys() and all(np.array_equal(x[key], y[key]) for key in x)
        for x, y in zip(a, b, strict=True)
    )


def cleo_agreement(contexts, random_seeds: int) -> None:
    """Every episode in spikectl and in Cleo: the differences, counted."""
    from spikectl.bridges.cleo import SETTINGS, CleoLoop

    env = NeuronControlEnv(contexts=contexts, extensions=SPIKES)
    loop = CleoLoop(contexts, SETTINGS["spikes-only"])
    makers = [("oracle", lambda seed: OraclePlanner(contexts, contexts.params))]
    makers += [(f"random seed {s}", lambda seed, s=s: RandomLegal(seed=s))
               for s in range(random_seeds)]  # fmt: skip
    started = time.perf_counter()
    print("| controller | episodes | different actions | different target spikes | "
          "different returns | different observations | mean return (both) |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, make in makers:
        counts = np.zeros(4, dtype=np.int64)
        returns = []
        for context in range(len(contexts)):
            ours = Recording(make(context))
            actions, total = play_episode(env, ours, context)
            spikes = env._spike_history[:, contexts[context].target].copy()
            theirs = Recording(make(context))
            episode = loop.play(theirs, context)
            counts += [
                not np.array_equal(episode.actions, actions),
                not np.array_equal(episode.target_spikes, spikes),
                episode.total != total,
                not same_observations(ours.seen, theirs.seen),
            ]
            returns.append(total)
        print(f"| {name} | {len(contexts)} | " + " | ".join(map(str, counts))
              + f" | {mean_and_error(np.array(returns))} |")  # fmt: skip
    print(f"wall-clock: {time.perf_counter() - started:.0f} s")


def decision_times(networks: int) -> None:
    """identify-and-plan on suite v2's ``spikes-only``: its mean return, CPU seconds and
    the percentiles of its decision times."""
    from spikectl.experiments.suite import suite_version, task

    contexts = load_split("spikes-only", "test", 2)[:networks]
    extensions = task("spikes-only", 2).extensions
    times: list[float] = []

    class Timed(IdentifyAndPlan):
        def act(self, observation, info) -> int:
            started = time.perf_counter()
            action = super().act(observation, info)
            times.append(time.perf_counter() - started)
            return action

        def spawn(self, index: int) -> Timed:  # one per network of the batch, timed too
            return Timed(self.params, self.composition, extensions=self.extensions,
                         seed=self.seed + index)  # fmt: skip

    controller = Timed(contexts.params, named_composition(extensions, contexts.n_observed),
                       extensions=extensions)  # fmt: skip
    started = time.process_time()
    returns = evaluate_policy(contexts, controller, extensions=extensions,
                              seed=suite_version(2).env_seed).returns  # fmt: skip
    seconds = time.process_time() - started
    ms = np.array(times) * 1e3
    print(f"identify-and-plan on spikes-only (suite v2, {networks} test networks): "
          f"{mean_and_error(returns)}, {seconds:.1f} CPU s, {ms.size} decisions, "
          f"median {np.percentile(ms, 50):.2f} ms, "
          f"99th percentile {np.percentile(ms, 99):.2f} ms")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cleo", action="store_true", help="also compare with Cleo")
    parser.add_argument("--random-seeds", type=int, default=2)
    parser.add_argument("--decisions", type=int, default=0,
                        help="time identify-and-plan's decisions on N v2 networks")  # fmt: skip
    arguments = parser.parse_args()
    if arguments.decisions:
        decision_times(arguments.decisions)
        return
    contexts = load_split("paper", "test")
    scores(contexts)
    if arguments.cleo:
        cleo_agreement(contexts, arguments.random_seeds)


if __name__ == "__main__":
    main()
