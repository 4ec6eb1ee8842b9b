"""Identify-and-plan's next action as per-neuron features (``spikectl.planning.advice``):
the planner's own actions, the guided teacher's labels, row independence, refusals."""

from __future__ import annotations

import numpy as np
import pytest

import spikectl
from spikectl.envs.controller import RandomLegal
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.params import NeuronParams
from spikectl.planning import BeliefInputs, PlannerAdvice, episode_beliefs
from spikectl.planning.advice import ADVICE_FEATURES
from spikectl.training.learners.teachers import teacher_labels


def _advice(contexts, episodes) -> np.ndarray:
    """float32 [E, N + 1, n, 2]: the advice at every observation of played episodes."""
    targets = np.array([c.observed_target for c in contexts])
    patterns = np.stack([c.pattern for c in contexts])
    return episode_beliefs(
        PlannerAdvice(NeuronParams()), episodes.voltage, episodes.actions, targets,
        patterns, episodes.action_mask,
    )  # fmt: skip


def _advised_actions(advice: np.ndarray) -> np.ndarray:
    """int [E, N]: the action each step's advice names (-1: do nothing)."""
    advised, waits = advice[:, :-1, :, 0], advice[:, :-1, :, 1]  # [E, N, n] each
    # exactly one: one neuron advised, or every neuron told to wait
    assert np.all((advised.sum(-1) == 1) ^ (waits.min(-1) == 1))
    assert np.all(waits.max(-1) == waits.min(-1))
    return np.where(waits[..., 0] == 1, -1, advised.argmax(-1))


def test_the_advice_is_the_planners_own_action_when_it_plays(splits):
    contexts = splits[1][:5]
    episodes = evaluate_policy(contexts, spikectl.IdentifyAndPlan(NeuronParams()))
    advice = _advice(contexts, episodes)
    assert advice.shape == (5, contexts.episode_length + 1, 8, len(ADVICE_FEATURES))
    assert np.array_equal(_advised_actions(advice), episodes.actions)
    assert not advice[:, -1].any()  # the last observation: the episode has ended
    assert (episodes.actions >= 0).any() and (episodes.actions == -1).any()


def test_the_advice_on_anothers_episodes_is_the_guided_teachers_label(splits):
    # The planner as a shadow: on episodes a random policy played, the advice at each
    # step is the label the guided learner's teacher gives (one computation, two routes),
    # and a row's advice does not depend on its batch.
    contexts = splits[1][:6]
    episodes = evaluate_policy(contexts, RandomLegal(seed=3))
    advice = _advice(contexts, episodes)
    labels = teacher_labels(episodes, list(contexts), "identify", NeuronParams(), None, 32)
    assert np.array_equal(_advised_actions(advice), labels)
    assert not np.array_equal(labels, episodes.actions)
    one = {"voltage": episodes.voltage[2:3], "actions": episodes.actions[2:3],
           "action_mask": episodes.action_mask[2:3]}  # fmt: skip
    alone = _advice(contexts[2:3], type("Episode", (), one))
    assert np.array_equal(alone[0], advice[2])


def test_advice_refuses_bad_inputs():
    with pytest.raises(TypeError, match="extensions must be an Extensions"):
        PlannerAdvice(NeuronParams(), 2.0)
    observations = {"voltage": np.full((2, 4), -70.0), "step": np.array([3, 3]),
                    "last_action": np.array([-1, -1]), "target": np.array([0, 1]),
                    "pattern": np.zeros((2, 10), np.int8)}  # fmt: skip
    with pytest.raises(ValueError, match="action_mask must have shape"):
        PlannerAdvice(NeuronParams())(observations, np.ones((2, 4), bool))
    with pytest.raises(ValueError, match="first step"):
        PlannerAdvice(NeuronParams())(observations, np.ones((2, 5), bool))
    with pytest.raises(ValueError, match="at least one part"):
        BeliefInputs([])


def test_the_advice_on_a_noisy_task_is_the_named_planner_of_that_task():
    # Under measurement noise the named identify-and-plan plays with the Bayes
    # observation model and filtered potentials (its composition "noise"); the advice is
    # that planner, so on its own episodes it names exactly the actions it took.
    from spikectl.envs.vector_env import NeuronControlVectorEnv
    from spikectl.experiments.suite import load_split, task

    contexts, extensions = load_split("noise2", "validation")[:4], task("noise2").extensions
    env = NeuronControlVectorEnv(num_envs=4, contexts=contexts, extensions=extensions)
    planner = spikectl.load_controller("identify-and-plan", env=env)
    assert planner.composition.name == "noise"
    episodes = evaluate_policy(contexts, planner, extensions=extensions, seed=0)
    targets = np.array([c.observed_target for c in contexts])
    patterns = np.stack([c.pattern for c in contexts])
    advice = episode_beliefs(
        PlannerAdvice(contexts.params, extensions), episodes.voltage, episodes.actions,
        targets, patterns, episodes.action_mask,
    )  # fmt: skip
    assert np.array_equal(_advised_actions(advice), episodes.actions)
    paper = PlannerAdvice(contexts.params)  # the paper's planner reads them otherwise
    played = (episodes.voltage, episodes.actions, targets, patterns, episodes.action_mask)
    advice = episode_beliefs(paper, *played)
    assert not np.array_equal(_advised_actions(advice), episodes.actions)
