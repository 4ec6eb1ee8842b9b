"""The belief input: identify-and-plan's identification as per-neuron features of a
learned policy (values on a hand-built network, row independence, the networks that read
it, every route that plays them, the replay that stores it)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from test_agents import SMALL, permute_neurons, random_obs, small_agent
from test_controllers import assert_same_play
from test_planning import feed_forward_probe

import spikectl
from spikectl.agents import export_policy, make_agent
from spikectl.agents.greedy import GreedyController
from spikectl.contexts.generation import connection_probability
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.params import NeuronParams
from spikectl.planning.belief import BELIEF_FEATURES, TargetInputBelief, episode_beliefs
from spikectl.training.presets import SMOKE
from spikectl.training.replay import EpisodeReplay


def _episode(weights: np.ndarray, actions: list[int]) -> tuple[np.ndarray, ...]:
    """(voltage [1, N + 1, n] from rest, actions [1, N], an empty pattern [1, N], every
    action legal [1, n + 1]) of one noise-free episode: the belief reads neither of the
    last two."""
    params = NeuronParams()
    after, _ = spikectl.simulate(weights, np.array(actions), params)  # [N, n] after each step
    n = weights.shape[0]
    rest = np.full((1, n), params.v_rest_mV)
    voltage = np.concatenate([rest, after]).astype(np.float32)[None]  # [1, N + 1, n]
    return voltage, np.array([actions]), np.zeros((1, len(actions))), np.ones((1, n + 1))


def test_the_belief_names_the_targets_inputs_on_a_hand_built_network():
    # Target 4 has excitatory inputs 1, 3 and 5. Stimulating 0, 1, 2 and 3 in turn
    # releases 0..4 (alone or told apart), so their synapses onto 4 become known; 5 never
    # releases, so its entry keeps the generator's prior.
    weights, actions = feed_forward_probe()
    voltage, played, pattern, legal = _episode(weights, actions)
    features = episode_beliefs(
        TargetInputBelief(NeuronParams()), voltage, played, np.array([4]), pattern, legal
    )
    assert features.shape == (1, len(actions) + 1, 6, len(BELIEF_FEATURES))
    excites, inhibits, uncertainty = np.moveaxis(features[0, -1], -1, 0)  # [n] each
    np.testing.assert_allclose(excites[[1, 3]], 1.0, atol=1e-6)
    np.testing.assert_allclose(excites[[0, 2]], 0.0, atol=1e-6)
    np.testing.assert_allclose(inhibits[:4], 0.0, atol=1e-6)
    assert (uncertainty[:4] < 0.05).all()
    # Neuron 5 (distance 1 from the target): the prior N(0, p), p = 0.3, untouched.
    prior_sd = math.sqrt(connection_probability(np.array(1)))
    untouched = 0.5 * math.erfc(0.5 / (prior_sd * math.sqrt(2)))
    assert excites[5] == pytest.approx(untouched, rel=1e-6)
    assert inhibits[5] == pytest.approx(untouched, rel=1e-6)
    assert uncertainty[5] == pytest.approx(1.0, abs=1e-9)
    # Before any observation every neuron is at its prior (the target's own entry too).
    assert np.all(features[0, 0, :, 2] == 1.0)
    # The features are read from observations only: the same episode with another
    # neuron named the target gives that neuron's column.
    column_3 = episode_beliefs(
        TargetInputBelief(NeuronParams()), voltage, played, np.array([3]), pattern, legal
    )
    np.testing.assert_allclose(column_3[0, -1, [1], 0], 1.0, atol=1e-6)  # 1 excites 3
    np.testing.assert_allclose(column_3[0, -1, [2], 1], 1.0, atol=1e-6)  # 2 inhibits 3


def test_a_rows_belief_does_not_depend_on_its_batch(splits):
    episodes = evaluate_policy(splits[1], spikectl.IdentifyAndPlan(NeuronParams()))
    targets = np.array([c.target for c in splits[1]])
    patterns = np.stack([c.pattern for c in splits[1]])
    together = episode_beliefs(
        TargetInputBelief(NeuronParams()), episodes.voltage, episodes.actions, targets,
        patterns, episodes.action_mask,
    )  # fmt: skip
    for row in (0, 7):
        one = slice(row, row + 1)
        alone = episode_beliefs(
            TargetInputBelief(NeuronParams()), episodes.voltage[one], episodes.actions[one],
            targets[one], patterns[one], episodes.action_mask[one],
        )  # fmt: skip
        assert np.array_equal(alone[0], together[row])
    # and it learns: at the end the true excitatory inputs stand out
    truth = np.stack([np.sign(c.weights[:, c.target]) for c in splits[1]])  # [S, n]
    final = together[:, -1, :, 0]
    assert final[truth > 0].mean() > 0.8 > 0.1 > final[truth <= 0].mean()


def test_belief_refuses_a_mid_episode_start_and_bad_noise():
    belief = TargetInputBelief(NeuronParams())
    observations = {"voltage": np.full((2, 4), -70.0), "step": np.array([3, 3]),
                    "last_action": np.array([-1, -1]), "target": np.array([0, 1])}  # fmt: skip
    with pytest.raises(ValueError, match="first step"):
        belief(observations)
    with pytest.raises(ValueError, match="noise_mV"):
        TargetInputBelief(NeuronParams(), noise_mV=-1.0)


def _with_belief(obs: dict[str, torch.Tensor], seed: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return {**obs, "belief": torch.rand(*obs["voltage"].shape, 3, generator=g, dtype=torch.float64)}


@pytest.mark.parametrize("name", ["ddrqn", "tdrqn"])
def test_a_network_reading_the_belief_is_equivariant_and_steps_as_it_runs(name):
    B, T, n = 3, 7, 5
    net = small_agent(name, n, belief_in_input=True).double()
    obs = _with_belief({k: v for k, v in random_obs(B, T, n, seed=2).items()}, seed=3)
    obs["voltage"] = obs["voltage"].double()
    q, _ = net(obs)
    perm = torch.tensor([2, 0, 4, 1, 3])
    permuted = {**permute_neurons(obs, perm), "belief": obs["belief"][:, :, perm]}
    q_p, _ = net(permuted)
    torch.testing.assert_close(q_p[..., 1:], q[..., 1:][..., perm], atol=1e-10, rtol=1e-10)
    # The belief reaches the Q-values.
    q_other, _ = net({**obs, "belief": 1.0 - obs["belief"]})
    assert not torch.allclose(q_other, q)
    # step by step = the sequence forward
    state = None
    for t in range(T):
        q_t, state = net.step({k: v[:, t] for k, v in obs.items()}, state)
        torch.testing.assert_close(q_t, q[:, t], atol=1e-10, rtol=1e-10)


def test_a_network_reading_the_belief_names_a_missing_or_misshapen_one():
    net = small_agent("tdrqn", 4, belief_in_input=True)
    obs = random_obs(2, 3, 4)
    with pytest.raises(ValueError, match=r"reads obs\['belief'\]"):
        net(obs)
    with pytest.raises(ValueError, match=r"obs\['belief'\] must have shape \[2, 3, 4, 3\]"):
        net({**obs, "belief": torch.zeros(2, 3, 4, 2)})


def test_what_does_not_compute_the_belief_refuses_it():
    with pytest.raises(ValueError, match="belief_in_input"):
        small_agent("drqn", 4, belief_in_input=True)
    with pytest.raises(ValueError, match="does not compute the belief"):
        export_policy(small_agent("tdrqn", 4, belief_in_input=True), "unused.npz")


def test_greedy_controller_with_a_belief_plays_each_context_as_alone(splits):
    # per_environment: every row plays as act() plays it alone, belief included (each row
    # is its own estimate, and the network runs on a batch of one), on every CPU.
    contexts = splits[1][:6]
    torch.manual_seed(4)
    net = make_agent("tdrqn", 8, contexts.episode_length, **{**SMALL, "belief_in_input": True})
    controller = GreedyController(net, per_environment=True,
                                  belief=TargetInputBelief(NeuronParams()))  # fmt: skip
    assert_same_play(controller, evaluate_policy(contexts, controller), contexts)
    # a batched forward plays it too; without its belief the network refuses to play
    batched = GreedyController(net, belief=TargetInputBelief(NeuronParams()))
    assert evaluate_policy(contexts, batched).actions.shape == (6, contexts.episode_length)
    with pytest.raises(ValueError, match=r"reads obs\['belief'\]"):
        evaluate_policy(contexts, GreedyController(net))


def test_replay_keeps_the_beliefs_and_restores_them():
    replay = EpisodeReplay(4, 3, 2, belief_width=3)
    voltage = np.zeros((2, 3, 3), dtype=np.float32)
    actions = np.full((2, 2), -1)
    other = (np.zeros((2, 2), np.float32), np.zeros(2, np.int64), np.zeros((2, 2), np.int8),
             np.ones((2, 4), bool))  # fmt: skip
    beliefs = np.arange(2 * 3 * 3 * 3, dtype=np.float32).reshape(2, 3, 3, 3)
    with pytest.raises(ValueError, match="needs beliefs"):
        replay.add(voltage, actions, *other)
    with pytest.raises(ValueError, match="beliefs must have shape"):
        replay.add(voltage, actions, *other, beliefs=beliefs[:, :2])
    replay.add(voltage, actions, *other, beliefs=beliefs)
    sample = replay.sample(5, np.random.default_rng(0))
    assert sample.beliefs.shape == (5, 3, 3, 3)
    assert all(any(np.array_equal(b, e) for e in beliefs) for b in sample.beliefs)
    restored = EpisodeReplay(4, 3, 2, belief_width=3)
    restored.load_state_dict(replay.state_dict())
    assert np.array_equal(restored.beliefs[:2], beliefs)
    with pytest.raises(ValueError, match="belief inputs"):
        EpisodeReplay(4, 3, 2).load_state_dict(replay.state_dict())


def trained_and_scored_again(changes: dict, run_dir) -> GreedyController:
    """Train SMOKE with ``changes`` into ``run_dir``, check that ``evaluate`` repeats the
    last evaluation of metrics.csv exactly, and return the run's loaded controller."""
    from spikectl.training.evaluate import evaluate_run
    from spikectl.training.run import train
    from spikectl.training.run_files import read_metrics

    # Four rounds, evaluated at episodes 0, 16 and 32: the last evaluation follows updates.
    train(SMOKE.with_changes(changes, n_val=3, total_env_steps=4 * 20 * 8,
                             eval_every_episodes=16), run_dir)  # fmt: skip
    final = read_metrics(run_dir)[-1]
    results = {result.name: result.mean for result in evaluate_run(run_dir)}
    assert results == {"train": final["train_return"], "test": final["test_return"],
                       "validation": final["val_return"]}  # fmt: skip
    return spikectl.load_controller(run_dir)


def test_training_with_the_belief_is_scored_again_exactly_by_evaluate(tmp_path):
    """The replay's beliefs (computed again from the stored episodes) and the
    controllers' (computed while playing) are one computation: evaluate repeats the
    last evaluation of metrics.csv exactly."""
    loaded = trained_and_scored_again({"agent.sizes.belief_in_input": True}, tmp_path / "run")
    assert [type(part) for part in loaded.belief.parts] == [TargetInputBelief]


def test_learners_that_cannot_store_the_belief_refuse_it():
    from test_pqn import pqn

    with pytest.raises(ValueError, match="belief_in_input needs a learner that stores it"):
        pqn(SMOKE.with_changes({"agent.sizes.belief_in_input": True}))
    with pytest.raises(ValueError, match="belief_in_input is read by the per-neuron"):
        SMOKE.with_changes({"agent.sizes.belief_in_input": True, "agent.arch": "drqn"})


@pytest.mark.parametrize(
    "flags, problem",
    [(["pqn", "--sizes.belief-in-input"], "belief-in-input needs a learner that stores it"),
     (["guided", "--arch", "drqn", "--sizes.belief-in-input"], "not by drqn"),
     (["quick", "--sizes.belief-in-input", "--seeds", "0", "1", "--stacked"],
      "does not compute the belief")],
)  # fmt: skip
def test_the_cli_refuses_what_cannot_read_the_belief_before_making_a_run(
    flags, problem, tmp_path, run_cli
):
    run = tmp_path / "run"
    result = run_cli("train", *flags, "--total-env-steps", "2000", "--run-dir", str(run),
                     check=False)  # fmt: skip
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert problem in lines[-1] and lines[-1].startswith("spikectl: error:")
    assert not run.exists()
