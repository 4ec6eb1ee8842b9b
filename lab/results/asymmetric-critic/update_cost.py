"""CPU time of one update of the guided learner (the main job's preset) with and without
the privileged critic, measured alternately in one process on one thread.

    python lab/results/asymmetric-critic/update_cost.py

Each learner's buffer holds the same 40 random-action episodes; an update is one
batch's loss, its gradient step and the soft update of the pairs the learner moves. The
median of 12 updates each (3 warm-up updates dropped).
"""

import dataclasses
import statistics
import time

import numpy as np
import torch

from spikectl.contexts import make_splits
from spikectl.envs.controller import RandomLegal, batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.training.learners.dqn_losses import soft_update
from spikectl.training.learners.guided import GuidedDQNLearner
from spikectl.training.learners.q_learning import gradient_step
from spikectl.training.presets import PRESETS

torch.set_num_threads(1)
base = PRESETS["guided"]
train_set = make_splits(40, 1, seed=0, n_val=0)[0]
learners = {}
for critic in (False, True):
    learner_config = dataclasses.replace(base.learner, asymmetric_critic=critic)
    config = dataclasses.replace(base, learner=learner_config)
    learner = GuidedDQNLearner(config, train_set, np.random.default_rng(0))
    episodes = evaluate_policy(train_set, batched(RandomLegal(seed=0)))
    learner.add_to_replay(episodes, np.arange(len(train_set)), None, learner.target_inputs)
    learners[critic] = learner
times = {False: [], True: []}
for _ in range(15):
    for critic, learner in learners.items():
        batch = learner.replay.sample(learner.settings.batch_size, learner.rng)
        start = time.process_time()
        gradient_step(learner, learner.batch_loss(batch, 10**9))
        for target, online in learner.soft_updated:
            soft_update(target, online, learner.settings.tau)
        times[critic].append(time.process_time() - start)
a, b = statistics.median(times[False][3:]), statistics.median(times[True][3:])
print(f"median CPU s per update: without {a:.4f}, with the critic {b:.4f}, ratio {b / a:.2f}")
