"""Does the told-weights teacher need to light neurons other than the target's inputs?
On the first NETWORKS networks of suite v2's ``chr2`` and ``paper`` VALIDATION sets
(never the test set): the told-weights teacher (the paper's composition told each
network's weights, beam 32: the guided learner's ``--teacher told-weights``) as it is,
and the same teacher with its legal actions cut to "do nothing" and the target's
excitatory inputs; paired network by network.

    python lab/results/chr2-learners/inputs_only.py [NETWORKS]
"""

from __future__ import annotations

import copy
import sys

import numpy as np

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.experiments.stats import paired_difference_cells
from spikectl.planning import Composition, IdentifyAndPlan

VERSION, SPLIT, WIDTH = 2, "validation", 32


class Told(IdentifyAndPlan):
    """The told-weights teacher of each played network; with ``inputs_only`` it may light
    only the target's excitatory inputs (or do nothing)."""

    def __init__(self, contexts, inputs_only: bool, **settings) -> None:
        super().__init__(**settings)
        self.contexts, self.inputs_only = contexts, inputs_only

    def spawn(self, index: int) -> IdentifyAndPlan:
        return copy.copy(self)

    def act(self, observation, info) -> int:
        context = self.contexts[int(info["context_index"])]
        weights = np.asarray(context.weights)
        if int(observation["step"]) == 0:
            self.told_weights = weights
        if self.inputs_only:
            mask = np.asarray(info["action_mask"]).astype(bool)
            mask[1:] &= weights[:, context.target] > 0
            info = {**info, "action_mask": mask.astype(np.int8)}
        return super().act(observation, info)


def main(networks: int) -> None:
    print(
        "| task | teacher | return | acting share | inputs only − free [95% CI] | better / worse |"
    )
    print("|---|---|---:|---:|---|---|")
    for task in ("chr2", "paper"):
        full = suite.load_split(task, SPLIT, VERSION)
        contexts = ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                              full.extensions)  # fmt: skip
        extensions = suite.task(task, VERSION).extensions
        returns = {}
        for inputs_only in (False, True):
            teacher = Told(contexts, inputs_only, composition=Composition().with_width(WIDTH),
                           extensions=extensions)  # fmt: skip
            episodes = evaluate_policy(contexts, teacher, extensions=extensions,
                                       seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
            returns[inputs_only] = episodes.returns
            label = "inputs only" if inputs_only else "free"
            difference = (paired_difference_cells(episodes.returns - returns[False])
                          if inputs_only else " | ")  # fmt: skip
            print(f"| {task} | {label} | {episodes.returns.mean():.3f} | "
                  f"{np.mean(episodes.actions >= 0):.3f} | {difference} |")  # fmt: skip


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
