"""The learners under spikes-only sensing (``Extensions(sensing="spikes")``, issue 60): an
agent reads each spike as a potential at threshold (``envs.sensing.with_sensed_potentials``),
so its normalised potential is the spike; the episodes store that, the PyTorch network and
its compiled policy act on it alike, runs train, resume and benchmark, and a guided run
whose teacher cannot play the environment is refused in one line."""

from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest
import torch

from spikectl.agents import greedy_action, make_agent, observation_batch
from spikectl.agents.compiled import CompiledPolicy
from spikectl.agents.features import normalised_voltage
from spikectl.agents.greedy import GreedyController
from spikectl.cli import main
from spikectl.config_errors import ConfigError
from spikectl.contexts import ContextSet
from spikectl.envs.controller import RandomLegal
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.envs.sensing import SPIKES_KEY, as_sensed, with_sensed_potentials
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.training.learners import GuidedConfig, PQNConfig, check_environment
from spikectl.training.learners.guided import teacher_composition
from spikectl.training.learners.teachers import teacher_refusal
from spikectl.training.presets import PRESETS, SMOKE
from spikectl.training.run import train
from spikectl.training.run_files import CLOCK_FIELDS, read_metrics

SPIKES_ONLY = Extensions(sensing="spikes")
SPIKES_ID = "spikectl/NeuronControlSpikesOnly-v0"
REST, THRESHOLD = NeuronParams().v_rest_mV, NeuronParams().v_threshold_mV
NEAR_TIE = 1e-5
"""As tests/test_compiled_policy.py: two legal Q-values closer than this may be ordered
either way by float rounding, so PyTorch and the compiled kernel may differ there."""
Q_TOLERANCE = 1e-5


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the machine's cores are shared
    yield
    torch.set_num_threads(threads)


def guided(config, **changes):
    learner = GuidedConfig(**{**dataclasses.asdict(config.learner), **changes})
    return dataclasses.replace(config, learner=learner)


# -- the reading, by hand


def test_a_spike_reads_as_the_potential_at_threshold():
    observation = {SPIKES_KEY: np.array([1, 0, 0, 1], np.int8), "target": 2,
                   "pattern": np.zeros(6, np.int8), "step": 3, "last_action": 1}  # fmt: skip
    read = with_sensed_potentials(observation, -70.0, -50.0)
    assert read["voltage"].dtype == np.float32
    assert read["voltage"].tolist() == [-50.0, -70.0, -70.0, -50.0]
    assert [key for key in read if key != "voltage"] == list(observation)
    assert all(read[key] is observation[key] for key in observation)
    assert "voltage" not in observation  # the caller's observation is left alone
    assert as_sensed(read) == observation
    # Other parameters: the normalised potential is still exactly the spike.
    read = with_sensed_potentials(observation, -65.0, -52.0)
    normalised = normalised_voltage(torch.as_tensor(read["voltage"]), -65.0, -52.0)
    assert normalised.tolist() == [1.0, 0.0, 0.0, 1.0]


def test_a_batch_reads_alike_and_potentials_are_left_as_they_are():
    batch = {SPIKES_KEY: np.array([[0, 1, 0], [0, 0, 0]], np.int8), "step": np.array([1, 1])}
    read = with_sensed_potentials(batch, REST, THRESHOLD)
    np.testing.assert_array_equal(read["voltage"], [[REST, THRESHOLD, REST], [REST] * 3])
    assert read["voltage"].shape == (2, 3) and read["voltage"].dtype == np.float32
    paper = {"voltage": np.array([-61.5, -50.0], np.float32), "step": 0}
    assert with_sensed_potentials(paper, REST, THRESHOLD) is paper
    assert as_sensed(paper) is paper


# -- the episodes the learners store


def test_the_stored_episodes_hold_threshold_at_each_spike_and_rest_elsewhere():
    """run_episodes stores V_th exactly where a neuron spiked and V_r elsewhere: the
    paper's spikes for the same actions; a bare policy reads the same potentials."""
    contexts = ContextSet.generate(6, n_neurons=8, seed=3)
    paper = evaluate_policy(contexts, RandomLegal(seed=1))
    seen, random = [], RandomLegal(seed=1)

    def policy(observations, action_mask):
        seen.append(observations["voltage"].copy())
        return random.act_batch(observations, {"action_mask": action_mask})

    spiking = evaluate_policy(contexts, RandomLegal(seed=1), extensions=SPIKES_ONLY)
    np.testing.assert_array_equal(spiking.actions, paper.actions)
    np.testing.assert_array_equal(spiking.spikes, paper.spikes)
    assert spiking.spikes.any() and spiking.voltage.dtype == np.float32
    assert (spiking.voltage[:, 0] == REST).all()
    expected = np.where(paper.spikes, np.float32(THRESHOLD), np.float32(REST))
    np.testing.assert_array_equal(spiking.voltage[:, 1:], expected)
    # The paper's potential reaches the threshold exactly where the spike is.
    np.testing.assert_array_equal(paper.voltage[:, 1:] >= THRESHOLD - 1e-6, paper.spikes)
    bare = evaluate_policy(contexts, policy, extensions=SPIKES_ONLY)
    np.testing.assert_array_equal(bare.actions, paper.actions)
    np.testing.assert_array_equal(np.stack(seen, axis=1), bare.voltage[:, :-1])


# -- the PyTorch network and its compiled policy


def test_the_network_and_its_compiled_policy_act_alike_on_spikes():
    """On spikes-only episodes GreedyController (PyTorch) and the compiled policy pick
    the same action wherever the best legal Q-value leads by NEAR_TIE (the two kernels
    sum in other orders: never bit-equal across them), Q-values within Q_TOLERANCE."""
    torch.manual_seed(0)
    network = make_agent("tdrqn", 8, 60, SMOKE.agent.sizes).eval()
    controller, compiled = GreedyController(network), CompiledPolicy.from_network(network)
    contexts = ContextSet.generate(6, n_neurons=8, seed=5)
    env = NeuronControlEnv(contexts=contexts, extensions=SPIKES_ONLY)
    rng = np.random.default_rng(0)
    flips_off_ties = steps = 0
    chosen, largest = set(), 0.0
    for index in range(len(contexts)):
        observation, info = env.reset(seed=index, options={"context": index})
        controller.reset()
        state, done = None, False
        while not done:
            assert "voltage" not in observation
            mask = info["action_mask"].astype(bool)
            action = controller.act(observation, info)
            read = with_sensed_potentials(observation, REST, THRESHOLD)
            with torch.no_grad():
                q, state = network.step(observation_batch([read]), state)  # [1, n + 1]
            # GreedyController is this very forward (one kernel, one batch size).
            assert action == int(greedy_action(q, torch.as_tensor(mask)[None])[0])
            other = compiled.act(observation, info)
            legal_q = np.sort(q[0].numpy()[mask])[::-1]
            near_tie = legal_q[0] - legal_q[1] < NEAR_TIE
            flips_off_ties += other != action and not near_tie
            largest = max(largest, float(np.abs(compiled.last_q - q[0].numpy()).max()))
            chosen.add(action)
            steps += 1
            # Random play reaches states (and spikes) greedy play would not.
            step_action = int(rng.choice(np.flatnonzero(mask)) - 1)
            observation, _, terminated, truncated, info = env.step(step_action)
            done = terminated or truncated
    assert steps == 6 * 60 and len(chosen) > 1
    assert flips_off_ties == 0 and largest < Q_TOLERANCE, (flips_off_ties, largest)


# -- training, resuming, benchmarking


SHORT = SMOKE.with_changes(
    {"env.id": SPIKES_ID, "total_env_steps": 6 * 8 * 20, "eval_every_episodes": 16,
     "checkpoint_every_episodes": 16}
)  # fmt: skip


def without_clocks(rows):
    return [{k: None if isinstance(v, float) and math.isnan(v) else v
             for k, v in row.items() if k not in CLOCK_FIELDS} for row in rows]  # fmt: skip


def test_a_run_on_spikes_trains_and_resumes_exactly(tmp_path, interrupt_after_rounds):
    assert SHORT.env.extensions.spikes_only
    whole = train(SHORT, tmp_path / "whole")
    assert whole[-1]["updates"] > 0 and all(math.isfinite(row["loss"]) for row in whole[1:])
    restore = interrupt_after_rounds(3)  # after the checkpoint at episode 16
    with pytest.raises(KeyboardInterrupt):
        train(SHORT, tmp_path / "stopped")
    restore()
    resumed = train(SHORT, tmp_path / "stopped", resume=True)
    assert without_clocks(resumed) == without_clocks(whole)


def learner_config(name: str):
    """SHORT with learner ``name``, its shared settings kept (the guided one untaught:
    its teacher's labels on spikes are checked on their own below, at a test's cost)."""
    if name == "dqn":
        return SHORT
    if name == "guided":
        return guided(SHORT, imitation_weight=0.0, imitation_weight_end=0.0)
    shared = {f.name for f in dataclasses.fields(PQNConfig)}
    settings = {k: v for k, v in dataclasses.asdict(SHORT.learner).items() if k in shared}
    sizes = dataclasses.replace(SHORT.agent.sizes, layer_norm=True)
    return dataclasses.replace(SHORT, agent=dataclasses.replace(SHORT.agent, sizes=sizes),
                               learner=PQNConfig(**settings))  # fmt: skip


@pytest.mark.parametrize("name", ["dqn", "pqn", "guided"])
def test_every_learner_trains_on_spikes(tmp_path, name):
    config = learner_config(name)
    assert config.learner.name == name and config.env.extensions.spikes_only
    rows = train(config, tmp_path / name)
    assert rows[-1]["updates"] > 0 and rows[-1]["env_steps"] == SHORT.train.total_env_steps
    assert all(math.isfinite(row["loss"]) for row in rows[1:])


def test_the_cli_trains_on_the_spikes_only_task_and_benchmarks_the_run(tmp_path, capsys):
    """``spikectl train --task spikes-only --suite 2`` trains on the task's sets; the
    benchmark of the run on the task's test split gives the run's last test return
    exactly (the same network, batch size and networks)."""
    run = tmp_path / "run"
    assert main(["train", "smoke", "--task", "spikes-only", "--suite", "2",
                 "--total-env-steps", "960", "--run-dir", str(run)]) in (0, None)  # fmt: skip
    last = read_metrics(run)[-1]
    out = tmp_path / "bench.csv"
    capsys.readouterr()
    code = main(["benchmark", str(run), "--suite", "2", "--task", "spikes-only",
                 "--out", str(out)])  # fmt: skip
    assert code in (0, None), capsys.readouterr()
    (row,) = list(csv.DictReader(out.open()))
    assert (row["suite_version"], row["task"]) == ("2", "spikes-only")
    assert abs(float(row["mean_return"]) - last["test_return"]) <= 5e-7  # the CSV's 6 places


# -- the teacher


def test_a_guided_run_is_refused_in_one_line_while_its_teacher_cannot_play(tmp_path):
    """Whatever teacher cannot play spikes-only sensing refuses the run before any
    directory, in one line that says why; the privileged teacher (told the weights,
    which identify-and-plan plays from potentials) never can. Identify-and-plan plays
    spikes at this size and teaches (not refused)."""
    for teacher in ("told-weights", "identify"):
        config = guided(SHORT, teacher=teacher)
        width = config.learner.teacher_width
        problem = teacher_refusal(config.env, teacher, width, teacher_composition(config))
        if teacher == "told-weights":
            assert problem is not None
        if problem is None:  # identify-and-plan identifies from spikes here
            check_environment([config])
            continue
        assert "\n" not in problem
        with pytest.raises(ConfigError, match="cannot teach on this environment") as error:
            train(config, tmp_path / teacher)
        assert error.value.path == ("learner", "teacher") and problem in str(error.value)
        assert "\n" not in str(error.value) and not (tmp_path / teacher).exists()
    # A run that never asks its teacher trains.
    untaught = guided(SHORT, teacher="told-weights", imitation_weight=0.0,
                      imitation_weight_end=0.0)  # fmt: skip
    assert not untaught.learner.teaches
    check_environment([untaught])


def test_the_cli_refuses_a_guided_run_on_spikes_naming_the_teacher(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "guided", "--task", "spikes-only", "--suite", "2", "--teacher",
              "told-weights", "--run-dir", str(tmp_path / "run")])  # fmt: skip
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1, error
    assert "--teacher 'told-weights' cannot teach on this environment" in error
    assert not (tmp_path / "run").exists()


def test_the_main_jobs_teacher_plays_the_papers_environment():
    """The README's main job (the guided preset) on potentials: its teacher plays, the
    run is not refused, and its config is the preset's as before."""
    config = PRESETS["guided"]
    assert config.learner.teaches and not config.env.extensions.spikes_only
    learner = config.learner
    composition = teacher_composition(config)
    assert teacher_refusal(config.env, learner.teacher, learner.teacher_width, composition) is None
    check_environment([config])


def test_the_teachers_labels_and_its_own_episodes_on_spikes_are_its_actions():
    """The guided learner's teacher, identify-and-plan made for spikes-only sensing, says
    what it did when labelling its own episodes (it sees the spikes the environment
    showed, not the potentials the agent reads), and plays them alike as the collection
    policy's teacher (the agent's added voltage taken away)."""
    from spikectl.envs.controller import batched
    from spikectl.envs.rollout import run_episodes
    from spikectl.envs.vector_env import NeuronControlVectorEnv
    from spikectl.planning import IdentifyAndPlan, named_composition
    from spikectl.training.learners.teachers import TeacherMixedPolicy, teacher_labels

    contexts = ContextSet.generate(3, n_neurons=6, seed=4)
    extensions = Extensions(sensing="spikes")
    composition = named_composition(extensions, 6, fast=True)
    assert composition.name == "spikes-fast" and composition.decision.gamble is None

    def make():
        return IdentifyAndPlan(contexts.params, composition, extensions=extensions)

    episodes = evaluate_policy(contexts, batched(make()), extensions=extensions, seed=1)
    labels = teacher_labels(episodes, list(contexts), "identify", contexts.params, extensions,
                            composition=composition)  # fmt: skip
    np.testing.assert_array_equal(labels, episodes.actions)
    assert (episodes.actions != -1).any()  # it acted, so the labels say something
    env = NeuronControlVectorEnv(num_envs=3, contexts=contexts, extensions=extensions)
    env.reset(seed=1)
    student = lambda observations, mask: np.full(len(mask), -1)  # noqa: E731
    mixed = TeacherMixedPolicy(student, np.ones(3, dtype=bool), make)
    np.testing.assert_array_equal(run_episodes(env, np.arange(3), mixed).actions,
                                  episodes.actions)  # fmt: skip
