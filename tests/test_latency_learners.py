"""Learners under loop latency (``Extensions.latency_steps``): the actions in flight that
the stored episodes rebuild are the ones the environment observed, the teacher's labels
are the teacher's own actions, and the ``actions-in-flight`` input feature reads them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from spikectl.agents.inputs import input_feature, input_width
from spikectl.contexts import make_splits
from spikectl.envs.controller import RandomLegal, batched
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.envs.rollout import evaluate_policy
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import MAX_LATENCY_STEPS, Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning import IdentifyAndPlan, named_composition
from spikectl.training.learners.q_learning import sequence_observations
from spikectl.training.learners.teachers import teacher_labels
from spikectl.training.replay import EpisodeBatchArrays, EpisodeReplay


def arrays(actions: np.ndarray, latency_steps: int, n: int = 4) -> EpisodeBatchArrays:
    size, length = actions.shape
    return EpisodeBatchArrays(
        voltage=np.zeros((size, length + 1, n), np.float32),
        actions=actions.astype(np.int64),
        rewards=np.zeros((size, length), np.float32),
        targets=np.zeros(size, np.int64),
        patterns=np.zeros((size, length), np.int8),
        action_masks=np.ones((size, n + 1), bool),
        latency_steps=latency_steps,
    )


def test_sequence_actions_in_flight_by_hand():
    """Observation t carries the actions chosen at t - L .. t - 1, oldest first."""
    obs = sequence_observations(arrays(np.array([[3, 1, -1, 2]]), 2), "cpu")
    assert obs[IN_FLIGHT_KEY].tolist() == [[[-1, -1], [-1, 3], [3, 1], [1, -1], [-1, 2]]]
    assert IN_FLIGHT_KEY not in sequence_observations(arrays(np.array([[3, 1]]), 0), "cpu")


@pytest.mark.parametrize("latency", [1, 2])
def test_rebuilt_actions_in_flight_are_the_observed_ones(latency):
    """Stored episodes (actions only) give back every observation's actions_in_flight as
    the latency environment showed it, through the replay buffer."""
    extensions = Extensions(latency_steps=latency)
    env = NeuronControlVectorEnv(3, contexts={"n_train": 3, "n_test": 1, "seed": 5},
                                 episode_length=12, extensions=extensions)  # fmt: skip
    observations, infos = env.reset(seed=1, options={"context": [0, 1, 2]})
    policy, seen, actions = RandomLegal(seed=2), [observations[IN_FLIGHT_KEY]], []
    for _ in range(env.episode_length):
        actions.append(policy.act_batch(observations, infos))
        observations, _, _, _, infos = env.step(actions[-1])
        seen.append(observations[IN_FLIGHT_KEY])
    replay = EpisodeReplay(8, env.n_observed, env.episode_length, latency_steps=latency)
    length, n = env.episode_length, env.n_observed
    replay.add(np.zeros((3, length + 1, n), np.float32), np.stack(actions, 1),
               np.zeros((3, length), np.float32), np.zeros(3, np.int64),
               np.zeros((3, length), np.int8), np.ones((3, n + 1), bool))  # fmt: skip
    rebuilt = sequence_observations(replay.sample(3, np.random.default_rng(0)), "cpu")
    assert replay.latency_steps == latency
    # The buffer holds the three episodes; match each sampled row to its episode.
    observed = np.stack(seen, 1)  # [3, N + 1, L]
    for row in rebuilt[IN_FLIGHT_KEY].numpy():
        assert any((row == episode).all() for episode in observed)


def test_actions_in_flight_feature_by_hand():
    feature = input_feature("actions-in-flight")
    assert feature.width == MAX_LATENCY_STEPS
    voltage = torch.zeros(2, 4)  # [B, n]
    obs = {IN_FLIGHT_KEY: torch.tensor([[2, -1], [0, 0]])}  # [B, L]
    columns = feature.compute(obs, voltage, torch.float32)  # [B, n, 5]
    expected = torch.zeros(2, 4, MAX_LATENCY_STEPS)
    expected[0, 2, 0] = 1.0  # lands on neuron 2 now; nothing after
    expected[1, 0, 0] = expected[1, 0, 1] = 1.0  # neuron 0 now and next step
    assert torch.equal(columns, expected)
    # Without latency the columns are zero, so one network plays every loop.
    assert not feature.compute({}, voltage, torch.float32).any()
    assert input_width(("target", "actions-in-flight")) == 2 + 1 + MAX_LATENCY_STEPS


@pytest.mark.parametrize("latency", [1, 2])
def test_teacher_labels_under_latency_are_the_teachers_actions(latency):
    """The guided learner's teacher, played beside its own episodes in a latency loop,
    says what it did: its labels read the actions in flight as it saw them."""
    contexts = make_splits(3, 1, seed=4, n_val=0)[0]
    extensions = Extensions(latency_steps=latency)
    composition = named_composition(extensions, 8, fast=True)
    teacher = IdentifyAndPlan(composition=composition, extensions=extensions)
    episodes = evaluate_policy(contexts, batched(teacher), extensions=extensions, seed=1)
    labels = teacher_labels(episodes, list(contexts), "identify", NeuronParams(), extensions,
                            composition=composition)  # fmt: skip
    np.testing.assert_array_equal(labels, episodes.actions)
    unaware = teacher_labels(episodes, list(contexts), "identify", NeuronParams(),
                             dataclasses.replace(extensions, latency_steps=0),
                             composition=composition)  # fmt: skip
    assert (unaware != episodes.actions).any()  # without them it would have taught otherwise


def test_train_task_of_suite_2():
    """``spikectl train --task T --suite 2`` trains on a v2 task's sets and loop; a v2
    task asked of v1 names the version it is in; each bad flag is one line."""
    from spikectl.cli.training import parse_train

    command = parse_train(["smoke", "--task", "latency2", "--suite", "2"])
    env = command.config.env
    assert env.extensions.latency_steps == 2 and env.n_neurons == 8
    assert (env.n_train, env.context_seed) == (1000, 2)
    assert parse_train(["smoke", "--suite=2", "--task=latency2"]).config.env == env
    with pytest.raises(ValueError, match="'latency1' is a task of suite v2"):
        parse_train(["smoke", "--task", "latency1"])
    for argv, message in [
        (["--suite", "2"], "--suite: give it with --task"),
        (["--task", "paper", "--suite", "two"], "--suite: a suite version number"),
        (["--task", "paper", "--suite", "1", "--suite", "2"], "--suite: one version per run"),
        (["--task"], "--task: give a task of the benchmark suite"),
        (["--task", "paper", "--suite"], "--suite: give a suite version"),
    ]:
        with pytest.raises(ValueError, match=message):
            parse_train(["smoke", *argv])
