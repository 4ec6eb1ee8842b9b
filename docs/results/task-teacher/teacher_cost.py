"""What the teacher's settings cost and change on each suite task: the guided learner's
identify teacher labels the same episodes with the task's settings (``teacher_settings
"task"``, ``environment_settings(..., fast=True)``) and with the constructor's
(``"defaults"``).

    python docs/results/task-teacher/teacher_cost.py > docs/results/task-teacher/teacher-cost.md

On each task, EPISODES episodes of a uniformly random legal policy on the first networks
of the task's training split (the states a student visits early in training), under the
task's extensions; CPU seconds of labelling per episode (``time.process_time``, one
thread) and the share of steps where the two teachers' labels differ.
"""

from __future__ import annotations

import time

import numpy as np

from spikectl.envs.controller import RandomLegal
from spikectl.envs.rollout import evaluate_policy
from spikectl.experiments.suite import load_split, suite_version, task
from spikectl.neuron.params import NeuronParams
from spikectl.planning.policy import environment_settings
from spikectl.training.learners.teachers import teacher_labels

EPISODES = 16
"""Episodes labelled per task."""


def main() -> None:
    print("| task | labelling CPU s per episode, task's settings | constructor's | ratio | "
          "steps labelled differently |")
    print("|---|---:|---:|---:|---:|")
    for name in suite_version(1).names():
        spec = task(name)
        contexts = load_split(name, "train")[:EPISODES]
        extensions = spec.extensions
        episodes = evaluate_policy(contexts, RandomLegal(0), extensions=extensions, seed=0)
        noise = extensions.observation_noise_mV
        seconds, labels = [], []
        for settings in (environment_settings(extensions, spec.n_observed, fast=True), {}):
            started = time.process_time()
            labels.append(teacher_labels(episodes, list(contexts), "identify", NeuronParams(),
                                         noise, settings=settings))  # fmt: skip
            seconds.append((time.process_time() - started) / EPISODES)
        differ = float(np.mean(labels[0] != labels[1]))
        print(f"| `{name}` | {seconds[0]:.3f} | {seconds[1]:.3f} | {seconds[0] / seconds[1]:.1f} | "
              f"{differ:.3f} |")


if __name__ == "__main__":
    main()
