"""What a trained student does on suite v2's ``chr2``, beside its told-weights teacher:
on the first NETWORKS networks of the VALIDATION set (never the test set), the run's
best network plays greedily while the told-weights teacher (the paper's composition
told each network's weights, beam 32, as ``--teacher told-weights`` labels) reads the
same observations, the student's actions included, and says what it would do.

    python lab/results/chr2-learners/diagnose_student.py RUN_DIR [NETWORKS]

Prints the student's return and how often it acts; how often the teacher acts in the
states the student visits; their agreement, on every step and on the steps the teacher
acts; where the student acts, how often the teacher acts too and how often on the same
neuron; and the share of each one's lit neurons that are excitatory inputs of the target.
(A network reading an input feature the core does not register cannot be loaded here.)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.planners.told import Told
from spikectl.contexts import ContextSet
from spikectl.envs.controller import Copies
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments import suite
from spikectl.planning import Composition
from spikectl.training.loaders import load_controller

TASK, VERSION, SPLIT, WIDTH = "chr2", 2, "validation", 32


class Beside:
    """The student acts; the teacher (a copy per network) reads the same observations and
    its choices are kept in ``labels`` (one [S] array per step)."""

    def __init__(self, student, teacher) -> None:
        self.student, self.teacher, self.labels = student, Copies(teacher), []

    def reset(self) -> None:
        self.student.reset()
        self.teacher.reset()
        self.labels = []

    def act_batch(self, observations, infos) -> np.ndarray:
        chosen = self.student.act_batch(observations, infos)
        self.labels.append(self.teacher.act_batch(observations, infos))
        return chosen

    def act(self, observation, info) -> int:
        raise NotImplementedError("played on the vector environment only")


def direct_share(actions: np.ndarray, contexts) -> float:
    hits = []
    for s, context in enumerate(contexts):
        inputs = np.asarray(context.weights)[:, context.target] > 0
        hits += inputs[actions[s][actions[s] >= 0]].tolist()
    return float(np.mean(hits)) if hits else float("nan")


def main(run_dir: str, networks: int) -> None:
    full = suite.load_split(TASK, SPLIT, VERSION)
    contexts = ContextSet([full[i] for i in range(networks)], full.params, full.seed,
                          full.extensions)  # fmt: skip
    extensions = suite.task(TASK, VERSION).extensions
    teacher = Told(contexts, composition=Composition().with_width(WIDTH), extensions=extensions)
    beside = Beside(load_controller(run_dir, model="best"), teacher)
    episodes = evaluate_policy(contexts, beside, extensions=extensions,
                               seed=suite.suite_version(VERSION).env_seed)  # fmt: skip
    chosen, labels = episodes.actions, np.stack(beside.labels, axis=1)  # [S, N]
    acts, teaches = chosen >= 0, labels >= 0
    print(f"{run_dir} on {networks} {TASK} validation networks: return "
          f"{episodes.returns.mean():.3f}; the student acts on {acts.mean():.3f} of steps, "
          f"its teacher on {teaches.mean():.3f} of the student's states")  # fmt: skip
    print(f"agreement {np.mean(chosen == labels):.3f}; on the teacher's acting steps "
          f"{np.mean(chosen[teaches] == labels[teaches]):.3f}")  # fmt: skip
    if acts.any():
        print(f"where the student acts, the teacher acts too on {teaches[acts].mean():.3f}, "
              f"on the same neuron {np.mean(chosen[acts] == labels[acts]):.3f} (one of "
              f"{np.asarray(episodes.action_mask).sum(1).mean() - 1:.0f} neurons)")  # fmt: skip
    print(f"lit neurons that are excitatory inputs of the target: student "
          f"{direct_share(chosen, list(contexts)):.2f}, teacher "
          f"{direct_share(labels, list(contexts)):.2f}")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 40)
