"""The guided learner's labels through the ChR2 actuator (``Extensions(actuator="chr2")``,
docs/results/chr2-learners): each teacher, labelling its own episodes after the fact,
says what it did, so the student's imitation targets sit on the observations the
teacher acted on (the light's effect, one step later and ~20 steps long, is tracked by
the teacher from the observations' last actions alone)."""

from __future__ import annotations

import numpy as np
import pytest

from spikectl.contexts import ContextSet
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.extensions import Extensions
from spikectl.planning import named_composition
from spikectl.training.learners.teachers import make_teacher, teacher_labels

CHR2 = Extensions(actuator="chr2")


@pytest.mark.parametrize("teacher", ["told-weights", "identify"])
def test_the_teachers_labels_of_its_own_chr2_episodes_are_its_actions(teacher):
    contexts = ContextSet.generate(3, n_neurons=6, episode_length=30, seed=5, extensions=CHR2)
    composition = named_composition(CHR2, 6, fast=True)
    labels, actions = [], []
    for context in contexts:  # the told-weights teacher knows one network's weights
        alone = ContextSet([context], contexts.params, contexts.seed, contexts.extensions)
        played = make_teacher(teacher, context, contexts.params, CHR2, 8, composition)
        episodes = evaluate_policy(alone, played, extensions=CHR2, seed=1)
        labels.append(teacher_labels(episodes, [context], teacher, contexts.params, CHR2, 8,
                                     composition=composition))  # fmt: skip
        actions.append(episodes.actions)
    np.testing.assert_array_equal(np.concatenate(labels), np.concatenate(actions))
    assert (np.concatenate(actions) >= 0).mean() > 0.05  # it lit neurons: the labels say something
