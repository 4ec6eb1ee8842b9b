"""The guided learner's oracle teacher (``--teacher oracle``): the oracle planner's
open-loop plan of each played network labels every step, for the loop's latency and
actuator, so a guided run trains where no teacher that identifies can play (the rig's
loop, suite v2 task ``rig``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from spikectl.cli import main
from spikectl.config_errors import ConfigError
from spikectl.contexts import make_splits
from spikectl.envs.controller import RandomLegal
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning.lit_search import planned_light
from spikectl.planning.oracle import OraclePlanner
from spikectl.training.learners import GuidedConfig, check_environment
from spikectl.training.learners.teachers import make_teacher, teacher_labels
from spikectl.training.presets import SMOKE
from spikectl.training.run import train

RIG_ID = "spikectl/NeuronControlRig-v0"
RIG = Extensions(actuator="chr2", latency_steps=2, sensing="spikes", background_rate=0.005)
WIDTH = 8
"""A narrow beam keeps the plans cheap; the labels' properties do not depend on it."""


@pytest.fixture(scope="module")
def contexts():
    return make_splits(4, 1, seed=3, n_val=0)[0]


def replay_labels(labels: np.ndarray):
    """A batched policy that plays ``labels[s, t]`` in sub-environment s at step t."""

    def policy(observations, action_mask):
        steps = np.asarray(observations["step"], dtype=np.int64)
        return labels[np.arange(len(labels)), steps].astype(np.int64)

    return policy


@pytest.mark.parametrize("extensions", [None, Extensions(latency_steps=2), RIG],
                         ids=["paper", "latency2", "rig"])  # fmt: skip
def test_the_oracles_labels_are_its_plan_whatever_the_episode(contexts, extensions):
    """Each episode's labels are the oracle planner's plan of its network for the
    loop's latency and light, step by step as the planner plays it, the same whatever
    the agent did (open loop), and legal."""
    params = NeuronParams()
    first = evaluate_policy(contexts, RandomLegal(1), extensions=extensions, seed=0)
    second = evaluate_policy(contexts, RandomLegal(2), extensions=extensions, seed=1)
    labels = teacher_labels(first, list(contexts), "oracle", params, extensions, WIDTH)
    np.testing.assert_array_equal(
        labels, teacher_labels(second, list(contexts), "oracle", params, extensions, WIDTH)
    )
    latency = 0 if extensions is None else extensions.latency_steps
    planner = OraclePlanner(contexts, params, WIDTH, light_mW_per_mm2=planned_light(extensions))
    for s in range(len(contexts)):
        np.testing.assert_array_equal(labels[s], planner.plan(s, latency))
    legal = np.take_along_axis(first.action_mask, labels.astype(np.int64) + 1, axis=1)
    assert labels.dtype == np.int16 and legal.all()
    # The teacher one episode makes acts as its labels say (it reads the latency from
    # the observation's actions in flight).
    teacher = make_teacher("oracle", contexts[0], params, extensions, WIDTH)
    first_step = {"step": 0, "voltage": np.zeros(8), "pattern": contexts[0].pattern}
    if latency:
        first_step["actions_in_flight"] = np.full(latency, -1)
    teacher.reset()
    assert teacher.act(first_step, {"action_mask": first.action_mask[0, 0],
                                    "context_index": 0}) == labels[0, 0]  # fmt: skip


def test_replayed_labels_score_like_the_oracle(contexts):
    """Played back through the loop they were planned for, the labels score what the
    oracle scores on the paper's task and far above doing nothing under latency."""
    params = NeuronParams()
    for extensions, least in ((None, 0.95), (Extensions(latency_steps=2), 0.85)):
        anything = evaluate_policy(contexts, RandomLegal(0), extensions=extensions, seed=0)
        labels = teacher_labels(anything, list(contexts), "oracle", params, extensions, WIDTH)
        played = evaluate_policy(contexts, replay_labels(labels), extensions=extensions, seed=0)
        assert played.returns.mean() >= least, (extensions, played.returns)


SHORT = SMOKE.with_changes(
    {"env.id": RIG_ID, "total_env_steps": 4 * 8 * 20, "eval_every_episodes": 16,
     "checkpoint_every_episodes": 16}
)  # fmt: skip


def guided(config, **changes):
    learner = GuidedConfig(**{**dataclasses.asdict(config.learner), **changes})
    return dataclasses.replace(config, learner=learner)


def test_a_guided_run_on_the_rig_trains_with_the_oracle_teacher(tmp_path):
    """On the rig's loop identify-and-plan cannot teach: the run is refused in one line
    that names the oracle teacher; with it the run trains, its labels come from the
    oracle (the student agrees with some of them) and its CPU counts."""
    assert SHORT.env.extensions.spikes_only and SHORT.env.extensions.latency_steps == 2
    refused = guided(SHORT, teacher="identify")
    with pytest.raises(ConfigError, match="train with --teacher oracle") as error:
        check_environment([refused])
    assert "\n" not in str(error.value)
    config = guided(SHORT, teacher="oracle", teacher_width=WIDTH, imitation_weight_end=0.5)
    check_environment([config])
    rows = train(config, tmp_path / "run")
    taught = [row for row in rows[1:] if not math.isnan(row["imitation_loss"])]
    assert taught and all(row["teacher_seconds"] > 0 for row in taught)
    assert all(0.0 <= row["teacher_agreement"] <= 1.0 for row in taught)


def test_the_cli_trains_guided_on_the_rig_with_the_oracle_teacher(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "guided", "--task", "rig", "--suite", "2",
              "--run-dir", str(tmp_path / "refused")])  # fmt: skip
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "--teacher oracle" in error, error
    assert not (tmp_path / "refused").exists()


def test_an_unknown_teacher_is_named(contexts):
    with pytest.raises(ConfigError, match="teacher"):
        GuidedConfig(teacher="witness")
    with pytest.raises(ValueError, match="unknown teacher 'witness'"):
        make_teacher("witness", contexts[0], NeuronParams(), None, WIDTH)
