"""The teacher-guided learner: its loss by hand, its teachers' labels, exact resume,
and that imitation teaches (``spikectl.training.learners.guided``)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from spikectl.config_errors import ConfigError
from spikectl.contexts import make_splits
from spikectl.envs.controller import RandomLegal, batched
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning import IdentifyAndPlan
from spikectl.training.config import Experiment
from spikectl.training.learners import GuidedConfig
from spikectl.training.learners.guided import large_margin_loss
from spikectl.training.learners.teachers import teacher_labels
from spikectl.training.presets import PRESETS, SMOKE
from spikectl.training.replay import NO_LABEL, EpisodeReplay
from spikectl.training.run import train
from spikectl.training.run_files import CLOCK_FIELDS

CLOCKS = (*CLOCK_FIELDS, "teacher_seconds")
ROOT = Path(__file__).resolve().parents[1]


def guided(config: Experiment = SMOKE, **changes) -> Experiment:
    learner = GuidedConfig(**{**dataclasses.asdict(config.learner), **changes})
    return dataclasses.replace(config, learner=learner)


def test_large_margin_loss_by_hand():
    q_values = torch.tensor([[[0.0, 0.3, 0.1, 0.9],  # teacher 0 (index 1): 0.9 + 0.2 - 0.3
                              [0.5, 0.2, 0.1, 0.0],  # teacher -1 leads by 0.3: 0
                              [0.4, 0.4, 0.4, 0.4]]])  # unlabelled  # fmt: skip
    labels = torch.tensor([[0, -1, NO_LABEL]])
    legal = torch.tensor([[[True, True, True, True]]])
    loss, agreement = large_margin_loss(q_values, labels, legal, margin=0.2)
    assert loss.item() == pytest.approx((0.8 + 0.0) / 2)
    assert agreement.item() == pytest.approx(0.5)  # step 1 agrees, step 0 does not
    # An illegal action's value does not count, however large.
    legal = torch.tensor([[[True, True, True, False]]])
    loss, agreement = large_margin_loss(q_values, labels, legal, margin=0.2)
    assert loss.item() == pytest.approx(0.0) and agreement.item() == 1.0
    # Without labelled steps both are 0 (not NaN).
    loss, agreement = large_margin_loss(q_values, torch.full((1, 3), NO_LABEL), legal, 0.2)
    assert loss.item() == 0.0 and agreement.item() == 0.0


def test_loss_gradient_moves_only_the_leading_and_teacher_actions():
    q_values = torch.tensor([[[0.0, 0.3, 0.1, 0.9]]], requires_grad=True)
    loss, _ = large_margin_loss(
        q_values, torch.tensor([[0]]), torch.ones(1, 1, 4, dtype=torch.bool), margin=0.2
    )
    loss.backward()
    assert q_values.grad.tolist() == [[[0.0, -1.0, 0.0, 1.0]]]


@pytest.fixture(scope="module")
def contexts():
    return make_splits(4, 1, seed=3, n_val=0)[0]


def test_labels_of_the_teachers_own_episodes_are_its_actions(contexts):
    """Played beside an episode it played itself, the teacher says what it did."""
    episodes = evaluate_policy(contexts, batched(IdentifyAndPlan()))
    labels = teacher_labels(episodes, list(contexts), "identify", NeuronParams())
    np.testing.assert_array_equal(labels, episodes.actions)
    episodes = evaluate_policy(contexts, told_weights_policy(contexts))
    labels = teacher_labels(episodes, list(contexts), "told-weights", NeuronParams())
    np.testing.assert_array_equal(labels, episodes.actions)


def told_weights_policy(contexts):
    """The loop told each context's weights, batched (context i in environment i)."""
    copies = [IdentifyAndPlan(told_weights=context.weights) for context in contexts]

    def policy(observations, action_mask):
        return np.array([
            copy.act({key: value[i] for key, value in observations.items()},
                     {"action_mask": action_mask[i]})
            for i, copy in enumerate(copies)
        ])  # fmt: skip

    return policy


def test_the_teacher_plays_the_training_tasks_settings():
    """With ``teacher_settings="task"`` (the default) the identify teacher is the named
    identify-and-plan of the training environment in its fast form; with ``"defaults"``
    (every earlier run's) the paper's composition; on the paper's task the two are the
    same."""
    from spikectl.planning import Composition, named_composition
    from spikectl.training.learners.guided import GuidedDQNLearner
    from spikectl.training.learners.teachers import make_teacher

    assert PRESETS["guided"].learner.teacher_settings == "task"
    assert GuidedConfig().teacher_settings == "task"
    noisy = Extensions(observation_noise_mV=2.0)
    for n_neurons, extensions in ((8, Extensions()), (8, noisy), (16, Extensions())):
        env = dataclasses.replace(SMOKE.env, n_neurons=n_neurons, extensions=extensions)
        train_set = make_splits(2, 1, n_neurons, 20, seed=0, n_val=0)[0]
        for choice in ("task", "defaults"):
            config = dataclasses.replace(guided(teacher_settings=choice), env=env)
            learner = GuidedDQNLearner(config, train_set, np.random.default_rng(0))
            expected = (named_composition(extensions, n_neurons, fast=True)
                        if choice == "task" else Composition())  # fmt: skip
            assert learner.teacher_composition == expected
            teacher = make_teacher("identify", train_set[0], NeuronParams(), extensions, 32,
                                   learner.teacher_composition)  # fmt: skip
            task = choice == "task"
            assert teacher.composition.observation.filter_voltage == (task and extensions == noisy)
            assert teacher.noise_mV == extensions.observation_noise_mV
            assert teacher.known_sd == (0.4 if task and n_neurons == 16 else 0.25)
            assert teacher.composition.decision.gamble is None
            assert make_teacher("identify", train_set[0], NeuronParams(), extensions, 8,
                                expected).composition.decision.width == 8  # fmt: skip
    # The paper's environment: the task's settings are the constructor's.
    assert GuidedDQNLearner(
        guided(teacher_settings="task"), make_splits(2, 1, seed=0, n_val=0)[0],
        np.random.default_rng(0),
    ).teacher_composition == Composition()  # fmt: skip
    with pytest.raises(ConfigError, match="teacher_settings"):
        Experiment.from_dict({"learner": {"name": "guided", "teacher_settings": "named"}})


def test_configs_saved_before_teacher_settings_read_back_as_they_ran():
    """A guided config saved before ``teacher_settings`` existed ran the constructor's
    teacher: it reads back as ``defaults`` where that differs from the task's settings,
    and as ``task`` (today's preset) on the paper's environment, where it does not."""
    results = ROOT / "docs" / "results" / "suite" / "trained" / "guided-upr24"
    for task, expected in (("paper", "task"), ("n16", "defaults"), ("noise1", "defaults"),
                           ("heterogeneous", "defaults")):  # fmt: skip
        saved = json.loads((results / task / "seed=0" / "config.json").read_text())
        assert "teacher_settings" not in saved["learner"]
        assert Experiment.from_dict(saved).learner.teacher_settings == expected
        saved["learner"]["teacher_settings"] = "task"  # a field the config names is kept
        assert Experiment.from_dict(saved).learner.teacher_settings == "task"
    # Today's configs name it, so they read back as saved.
    config = guided(teacher_settings="defaults")
    assert Experiment.from_dict(config.to_dict()) == config


def test_labels_under_noise_with_the_tasks_settings_are_the_teachers_actions():
    """Label exactness holds for the task's teacher too: under measurement noise the
    named controller's fast form, played beside its own episodes, says what it did."""
    from spikectl.planning import named_composition

    contexts = make_splits(3, 1, seed=4, n_val=0)[0]
    noisy = Extensions(observation_noise_mV=2.0)
    composition = named_composition(noisy, 8, fast=True)
    episodes = evaluate_policy(
        contexts, batched(IdentifyAndPlan(composition=composition, extensions=noisy)),
        extensions=noisy, seed=1,
    )  # fmt: skip
    labels = teacher_labels(episodes, list(contexts), "identify", NeuronParams(), noisy,
                            composition=composition)  # fmt: skip
    np.testing.assert_array_equal(labels, episodes.actions)
    plain = teacher_labels(episodes, list(contexts), "identify", NeuronParams(), noisy)
    assert (plain != episodes.actions).any()  # the defaults would have taught otherwise


def test_teachers_label_other_trajectories_legally(contexts):
    episodes = evaluate_policy(contexts, RandomLegal(1))
    for teacher in ("identify", "told-weights"):
        labels = teacher_labels(episodes, list(contexts), teacher, NeuronParams())
        assert labels.shape == episodes.actions.shape
        legal = np.take_along_axis(episodes.action_mask, labels.astype(np.int64) + 1, axis=1)
        assert legal.all()


def test_told_weights_loop_scores_near_the_oracle():
    contexts = make_splits(12, 1, seed=5, n_val=0)[0]
    told = evaluate_policy(contexts, told_weights_policy(contexts)).returns
    identify = evaluate_policy(contexts, batched(IdentifyAndPlan())).returns
    assert told.mean() >= 0.97 and told.mean() > identify.mean()


def test_told_weights_are_checked():
    with pytest.raises(ValueError, match="told_weights must be a square"):
        IdentifyAndPlan(told_weights=np.zeros((3, 4)))
    with pytest.raises(ValueError, match="only -1, 0 and \\+1"):
        IdentifyAndPlan(told_weights=np.full((3, 3), 2))


def test_labelled_replay_round_trip_and_mismatch():
    replay = EpisodeReplay(4, 3, 5, labelled=True)
    voltage = np.zeros((2, 6, 3), np.float32)
    actions = np.full((2, 5), -1)
    args = (voltage, actions, np.zeros((2, 5)), np.zeros(2, int), np.zeros((2, 5)),
            np.ones((2, 4), bool))  # fmt: skip
    replay.add(*args, labels=np.arange(10).reshape(2, 5) % 3)
    replay.add(*args)  # unlabelled episodes
    copy = EpisodeReplay(4, 3, 5, labelled=True)
    copy.load_state_dict(replay.state_dict())
    np.testing.assert_array_equal(copy.labels, replay.labels)
    assert (copy.labels[2:] == NO_LABEL).all()
    with pytest.raises(ValueError, match="keeps teacher labels"):
        EpisodeReplay(4, 3, 5).load_state_dict(replay.state_dict())
    with pytest.raises(ValueError, match="keeps no labels"):
        EpisodeReplay(4, 3, 5).add(*args, labels=np.zeros((2, 5)))


def test_config_checks_and_round_trip():
    config = guided(teacher="told-weights", imitation_margin=0.1)
    again = Experiment.from_dict(json.loads(json.dumps(config.to_dict())))
    assert again == config and type(again.learner) is GuidedConfig
    assert config.to_dict()["learner"]["name"] == "guided"
    with pytest.raises(ConfigError, match="teacher"):
        GuidedConfig(teacher="witness")
    with pytest.raises(ConfigError, match="imitation_margin"):
        GuidedConfig(imitation_margin=-1.0)
    with pytest.raises(ConfigError, match="imitation_anneal_fraction"):
        GuidedConfig(imitation_anneal_fraction=1.5)
    schedule = GuidedConfig(imitation_weight=2.0, imitation_weight_end=0.5,
                            imitation_anneal_fraction=0.5)  # fmt: skip
    assert [schedule.imitation_weight_at(e, 100) for e in (0, 25, 50, 90)] == [2.0, 1.25, 0.5, 0.5]
    assert type(PRESETS["guided"].learner) is GuidedConfig


def test_stacked_groups_refuse_the_guided_learner(tmp_path):
    from spikectl.training.learners import make_learners

    with pytest.raises(ValueError, match="guided learner has no stacked form"):
        make_learners([guided()], [None], [None], stacked=True)


SHORT = guided(
    SMOKE.with_changes(
        total_env_steps=6 * 20 * 8, eval_every_episodes=16, checkpoint_every_episodes=16
    ),  # fmt: skip
    teacher="told-weights",
    imitation_anneal_fraction=0.5,
)


def test_guided_run_resumes_exactly(tmp_path, interrupt_after_rounds):
    reference = train(SHORT, tmp_path / "reference")
    assert reference[1]["imitation_weight"] < 1.0 and reference[-1]["imitation_weight"] == 0.0
    assert reference[1]["teacher_seconds"] > 0 and not math.isnan(reference[1]["imitation_loss"])
    assert math.isnan(reference[-1]["imitation_loss"])  # weaned: TD only
    restore = interrupt_after_rounds(3)  # after the checkpoint at episode 16
    with pytest.raises(KeyboardInterrupt):
        train(SHORT, tmp_path / "killed")
    restore()
    resumed = train(SHORT, tmp_path / "killed", resume=True)

    def without_clocks(rows):
        return [
            {k: None if isinstance(v, float) and math.isnan(v) else v
             for k, v in row.items() if k not in CLOCKS}
            for row in rows
        ]  # fmt: skip

    assert without_clocks(resumed) == without_clocks(reference)


def test_imitation_teaches_the_teachers_actions(tmp_path):
    """Imitation outweighing the TD loss: the student's agreement with the teacher on
    the labelled steps it samples climbs (0.42 -> 0.63 over these 160 episodes)."""
    config = guided(
        SMOKE.with_changes(
            total_env_steps=20 * 20 * 8,
            eval_every_episodes=32,
            checkpoint_every_episodes=160,
            learning_rate=3e-3,
        ),  # fmt: skip
        teacher="identify",
        imitation_weight=10.0,
        imitation_weight_end=10.0,
        imitation_margin=0.1,
    )
    rows = train(config, tmp_path / "run")
    agreement = [row["teacher_agreement"] for row in rows[1:]]
    assert agreement[-1] > agreement[0] + 0.15


def test_cli_guided_preset_flags_and_errors(capsys):
    from spikectl.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["train", "guided", "--teacher", "witness", "--run-dir", "unused"])
    assert exit_info.value.code == 2
    assert "identify" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "guided", "--imitation-margin", "-1", "--run-dir", "unused"])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--imitation-margin" in line and ">= 0" in line
    # The quick preset's learner has no teacher.
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "quick", "--teacher", "identify", "--run-dir", "unused"])
    assert exit_info.value.code == 2


def test_teacher_plays_its_episodes_and_the_student_the_others(contexts):
    """DAgger's mixing, per episode: where the teacher plays, the episode is identify-and-
    plan's own; elsewhere it is the student's, draws and all; the teacher's episodes are
    labelled with their actions without playing the teacher again."""
    from spikectl.training.learners.teachers import TeacherMixedPolicy

    plays = np.array([True, False, True, False])
    student = batched(RandomLegal(5))
    student.reset()
    mixed = TeacherMixedPolicy(
        lambda observations, mask: student.act_batch(observations, {"action_mask": mask}),
        plays, IdentifyAndPlan,
    )  # fmt: skip
    episodes = evaluate_policy(contexts, mixed)
    teacher_alone = evaluate_policy(contexts, batched(IdentifyAndPlan()))
    student_alone = evaluate_policy(contexts, batched(RandomLegal(5)))
    np.testing.assert_array_equal(episodes.actions[plays], teacher_alone.actions[plays])
    np.testing.assert_array_equal(episodes.actions[~plays], student_alone.actions[~plays])
    assert mixed.teacher_seconds > 0
    labels = teacher_labels(episodes, list(contexts), "identify", NeuronParams(), played=plays)
    np.testing.assert_array_equal(labels, teacher_labels(episodes, list(contexts), "identify",
                                                         NeuronParams()))  # fmt: skip


def test_teacher_episodes_schedule_and_checks():
    config = GuidedConfig(teacher_episodes=0.5, imitation_anneal_fraction=0.5)
    assert [config.teacher_share_at(e, 100) for e in (0, 25, 50, 90)] == [0.5, 0.25, 0.0, 0.0]
    assert GuidedConfig().teacher_share_at(0, 100) == 0.0
    with pytest.raises(ConfigError, match="teacher_episodes"):
        GuidedConfig(teacher_episodes=1.5)
    with pytest.raises(ConfigError, match="only teacher 'identify' can play"):
        GuidedConfig(teacher="told-weights", teacher_episodes=0.5)


def test_run_with_teacher_episodes_resumes_exactly(tmp_path, interrupt_after_rounds):
    config = dataclasses.replace(
        SHORT,
        learner=dataclasses.replace(
            SHORT.learner, teacher="identify", teacher_episodes=1.0
        ),  # fmt: skip
    )
    # The first round is all the teacher's, the last (past the anneal) all the student's.
    from spikectl.training.learners.guided import GuidedDQNLearner
    from spikectl.training.learners.teachers import TeacherMixedPolicy

    learner = GuidedDQNLearner(config, make_splits(6, 1, 5, 20, seed=0, n_val=0)[0],
                               np.random.default_rng(0))  # fmt: skip
    first = learner.collection_policy(0)
    assert isinstance(first, TeacherMixedPolicy) and first.teacher_plays.all()
    assert not isinstance(learner.collection_policy(config.total_episodes - 1),
                          TeacherMixedPolicy)  # fmt: skip
    reference, resumed = trained_and_resumed(config, tmp_path, interrupt_after_rounds)
    assert reference[1]["teacher_seconds"] > 0
    assert without_clocks_or_nan(resumed) == without_clocks_or_nan(reference)


def trained_and_resumed(config, tmp_path, interrupt_after_rounds):
    """The metrics of a run trained in one go and of the same run killed after 3 rounds
    and resumed."""
    reference = train(config, tmp_path / "reference")
    restore = interrupt_after_rounds(3)
    with pytest.raises(KeyboardInterrupt):
        train(config, tmp_path / "killed")
    restore()
    return reference, train(config, tmp_path / "killed", resume=True)


def without_clocks_or_nan(rows):
    return [
        {k: v for k, v in row.items()
         if k not in CLOCKS and not (isinstance(v, float) and math.isnan(v))}
        for row in rows
    ]  # fmt: skip


def test_connectivity_loss_by_hand_and_head_shapes():
    from spikectl.agents import make_agent, make_connectivity_predictor
    from spikectl.training.learners.guided import connectivity_loss

    class Constant(torch.nn.Module):
        def forward(self, features):  # logits favouring "excitatory" by ln 2
            logits = torch.zeros(*features.shape[:3], 3)
            logits[..., 2] = math.log(2.0)
            return logits

    features = torch.zeros(1, 2, 2, 5)  # [B, T, n, D]
    target_inputs = torch.tensor([[1, -1]])  # neuron 0 excites the target, 1 inhibits it
    # p(excitatory) = 2/4, p(inhibitory) = 1/4: mean of -ln(1/2) and -ln(1/4) at both steps.
    expected = (math.log(2.0) + math.log(4.0)) / 2
    loss = connectivity_loss(Constant(), features, target_inputs)
    assert loss.item() == pytest.approx(expected)
    for arch, n in (("tdrqn", 5), ("drqn", 4)):
        network = make_agent(arch, n, 6)
        obs_seq = {
            "voltage": torch.full((2, 3, n), -70.0),
            "last_action": torch.full((2, 3), -1),
            "step": torch.arange(3).expand(2, -1),
            "target": torch.zeros(2, 3, dtype=torch.long),
            "pattern": torch.zeros(2, 3, 6),
        }
        encoded, _ = network.encode(obs_seq)
        assert make_connectivity_predictor(network)(encoded).shape == (2, 3, n, 3)


def test_privileged_replay_round_trip_and_mismatch():
    replay = EpisodeReplay(4, 3, 5, privileged=True)
    args = (np.zeros((2, 6, 3), np.float32), np.full((2, 5), -1), np.zeros((2, 5)),
            np.zeros(2, int), np.zeros((2, 5)), np.ones((2, 4), bool))  # fmt: skip
    replay.add(*args, target_inputs=np.array([[1, 0, -1], [0, 1, 0]], np.int8))
    copy = EpisodeReplay(4, 3, 5, privileged=True)
    copy.load_state_dict(replay.state_dict())
    np.testing.assert_array_equal(copy.target_inputs[:2], [[1, 0, -1], [0, 1, 0]])
    assert copy.sample(3, np.random.default_rng(0)).target_inputs.shape == (3, 3)
    with pytest.raises(ValueError, match="needs target_inputs"):
        replay.add(*args)
    with pytest.raises(ValueError, match="target_inputs must have shape"):
        replay.add(*args, target_inputs=np.zeros((2, 4), np.int8))
    with pytest.raises(ValueError, match="keeps the target's inputs"):
        EpisodeReplay(4, 3, 5).load_state_dict(replay.state_dict())
    state = replay.state_dict()
    state["target_inputs"][0, 0] = 2
    with pytest.raises(ValueError, match="target_inputs lie outside"):
        EpisodeReplay(4, 3, 5, privileged=True).load_state_dict(state)


def test_connectivity_labels_are_the_target_column_of_the_observed_neurons():
    from spikectl.training.learners.guided import GuidedDQNLearner

    train_set = make_splits(3, 1, 5, 20, seed=0, n_val=0)[0]
    config = guided(SMOKE.with_changes(n_neurons=5), connectivity_weight=0.5)
    learner = GuidedDQNLearner(config, train_set, np.random.default_rng(0))
    for row, context in zip(learner.target_inputs, train_set, strict=True):
        np.testing.assert_array_equal(row, np.sign(context.weights[:, context.target]))
    assert learner.replay.target_inputs is not None
    assert any(p is q for p in learner.trained for q in learner.connectivity_head.parameters())
    with pytest.raises(ConfigError, match="connectivity_weight"):
        GuidedConfig(connectivity_weight=-0.1)
    plain = GuidedDQNLearner(guided(SMOKE.with_changes(n_neurons=5)), train_set,
                             np.random.default_rng(0))  # fmt: skip
    assert plain.connectivity_head is None and plain.replay.target_inputs is None


def test_connectivity_loss_learns_and_the_run_resumes_exactly(tmp_path, interrupt_after_rounds):
    """The head learns the target's inputs (its loss falls well below the uniform
    guess's ln 3 = 1.10) and a run with it resumes bit for bit."""
    config = dataclasses.replace(
        SHORT, learner=dataclasses.replace(SHORT.learner, connectivity_weight=1.0)
    )
    reference, resumed = trained_and_resumed(config, tmp_path, interrupt_after_rounds)
    losses = [row["connectivity_loss"] for row in reference[1:]]
    assert losses[0] < 1.10 and losses[-1] < losses[0] - 0.1
    assert without_clocks_or_nan(resumed) == without_clocks_or_nan(reference)
    assert all(math.isnan(row["connectivity_loss"]) for row in train(SHORT, tmp_path / "off"))
