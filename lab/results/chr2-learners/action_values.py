"""How much each of the told-weights teacher's actions is worth on suite v2's ``chr2``,
beside the paper's task: on the first NETWORKS networks of each task's VALIDATION set
(never the test set), the teacher plays each network once; then, for up to STEPS of the
steps where it acted, the same episode is played again with "do nothing" forced at that
step alone (the teacher replans from the state it meets, as when it labels the
student's episodes). The drop in return is the worth of the labelled action over
doing nothing: what the guided learner's imitation and its TD targets have to find.

    python lab/results/chr2-learners/action_values.py [NETWORKS [STEPS]]
"""

from __future__ import annotations

import copy
import sys

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import Composition, IdentifyAndPlan

VERSION, SPLIT, WIDTH = 2, "validation", 32


class ForcedTold(IdentifyAndPlan):
    """The told-weights teacher of ``contexts[network[row]]`` in each row of a batch,
    forced to do nothing at step ``forced[row]`` (-1: never)."""

    def __init__(self, contexts, network, forced, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self.network, self.forced, self.row = contexts, network, forced, -1

    def spawn(self, index: int) -> IdentifyAndPlan:
        child = copy.copy(self)
        child.row = index
        return child

    def act(self, observation, info) -> int:
        step = int(observation["step"])
        if step == 0:
            self.told_weights = np.asarray(self.contexts[int(self.network[self.row])].weights)
        action = super().act(observation, info)  # the teacher's tracking sees every step
        return -1 if step == self.forced[self.row] else action


def play(task: str, contexts: ContextSet, network: np.ndarray, forced: np.ndarray):
    rows = ContextSet([contexts[int(i)] for i in network], contexts.params, contexts.seed,
                      contexts.extensions)  # fmt: skip
    extensions = suite.task(task, VERSION).extensions
    teacher = ForcedTold(contexts, network, forced, composition=Composition().with_width(WIDTH),
                         extensions=extensions)  # fmt: skip
    return evaluate_policy(rows, teacher, extensions=extensions,
                           seed=suite.suite_version(VERSION).env_seed)  # fmt: skip


def main(networks: int = 20, steps: int = 8) -> None:
    rng = np.random.default_rng(0)
    for task in ("chr2", "paper"):
        full = suite.load_split(task, SPLIT, VERSION)
        contexts = ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                              full.extensions)  # fmt: skip
        index = np.arange(networks)
        base = play(task, contexts, index, np.full(networks, -1))
        network, forced = [], []
        for s in range(networks):
            acting = np.flatnonzero(base.actions[s] >= 0)
            for t in rng.permutation(acting)[:steps]:
                network.append(s)
                forced.append(int(t))
        network, forced = np.array(network), np.array(forced)
        episodes = play(task, contexts, network, forced)
        drop = base.returns[network] - episodes.returns
        per_wanted = np.mean([np.asarray(c.pattern).sum() for c in contexts])
        print(f"{task}: teacher {base.returns.mean():.3f} on {networks} networks; forcing "
              f"'do nothing' at one of its action steps ({len(drop)} cases): return drop "
              f"mean {drop.mean():.4f}, median {np.median(drop):.4f}, share < 0.005: "
              f"{np.mean(drop < 0.005):.2f}, share < 0: {np.mean(drop < 0):.2f} "
              f"(one wanted spike is worth {0.5 / per_wanted:.4f})")  # fmt: skip


if __name__ == "__main__":
    arguments = [int(value) for value in sys.argv[1:3]]
    main(*arguments)
