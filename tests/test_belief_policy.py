"""The policy on the amortised belief (issue 61, item 2): its NumPy forward is the PyTorch
net's, relabelling the neurons relabels its scores, its inputs on a hand-built step are
the hand-computed ones, it acts legally and alone as in a batch, a saved file plays as
the policy in memory through ``load_controller``, and a bad file is one line."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import run_main

import spikectl
from spikectl import ContextSet
from spikectl.agents.amortised_belief import AmortisedBelief
from spikectl.agents.amortised_controller import AmortisedController, BeliefWeightsError
from spikectl.agents.amortised_kernel import BeliefFeatureTracker, BeliefKernel, target_prior
from spikectl.agents.belief_policy import (
    AHEAD_STEPS,
    N_POLICY_FEATURES,
    NEURON_FEATURES,
    STEP_FEATURES,
    BeliefPolicyController,
    BeliefPolicyNet,
    PolicyKernel,
    load_belief_policy,
    policy_features,
    save_belief_policy,
)
from spikectl.envs.controller import play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.params import NeuronParams


def drawn(module: torch.nn.Module, seed: int, scale: float = 0.5) -> torch.nn.Module:
    """``module`` with every weight drawn from N(0, scale^2)."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in module.parameters():
            parameter.copy_(scale * torch.randn(parameter.shape, generator=generator))
    return module.eval()


def random_net(seed: int, width: int = 16) -> BeliefPolicyNet:
    return drawn(BeliefPolicyNet(width), seed)


def random_belief(seed: int) -> AmortisedBelief:
    return drawn(AmortisedBelief(8, 4, 1), seed)


@pytest.mark.parametrize("n_neurons", [5, 13])
def test_the_numpy_forward_equals_the_torch_net(n_neurons):
    net = random_net(n_neurons)
    features = np.random.default_rng(n_neurons).normal(size=(n_neurons, N_POLICY_FEATURES))
    features[:, len(NEURON_FEATURES):] = features[0, len(NEURON_FEATURES):]  # one step's facts
    features = features.astype(np.float32)
    with torch.no_grad():
        expected = net(torch.from_numpy(features)[None])[0].numpy()
    np.testing.assert_allclose(PolicyKernel(net).scores(features), expected, atol=2e-5)


def test_relabelling_the_neurons_relabels_the_scores():
    net, rng = PolicyKernel(random_net(1)), np.random.default_rng(3)
    features = rng.normal(size=(9, N_POLICY_FEATURES)).astype(np.float32)
    features[:, len(NEURON_FEATURES):] = features[0, len(NEURON_FEATURES):]
    order = rng.permutation(9)
    scores, permuted = net.scores(features), net.scores(features[order])
    assert permuted[0] == pytest.approx(scores[0], abs=1e-9)  # do nothing: pooled, unmoved
    np.testing.assert_allclose(permuted[1:], scores[1:][order], atol=1e-9)


def test_the_features_of_a_hand_built_step():
    p = NeuronParams()
    n, target, step = 5, 2, 3
    tracker = BeliefFeatureTracker(n, target, p)
    tracker.state[0] = [0, 1, 9, 3, 9]  # steps since each neuron's last release
    tracker.state[1] = p.v_rest_mV
    tracker.state[1, 4] = p.v_spike_mV - 1.0  # neuron 4 one millivolt below threshold
    tracker.state[2] = [2, 0, 0, 0, 0]  # neuron 0 refractory for 2 more steps
    probabilities = np.array([[0.2, 0.7, 0.1], [0.5, 0.4, 0.1], [1, 0, 0], [0.9, 0.1, 0.0],
                              [0.6, 0.3, 0.1]])  # fmt: skip
    legal = np.array([True, True, False, True, True])
    can_land = np.array([False, False, False, True, True])
    pattern = np.zeros(60, dtype=bool)
    pattern[[4, 9, 10]] = True
    out = policy_features(probabilities, legal, can_land, tracker, pattern, step, p, 3)
    interval, span = p.min_release_interval_steps, p.v_spike_mV - p.v_rest_mV
    column = {name: k for k, name in enumerate(NEURON_FEATURES + STEP_FEATURES)}
    np.testing.assert_array_equal(out[:, :3], probabilities.astype(np.float32))
    np.testing.assert_array_equal(out[:, column["legal"]], legal)
    np.testing.assert_array_equal(out[:, column["can_land"]], can_land)
    np.testing.assert_allclose(out[:, column["refractory"]], [2 / p.refractory_steps, 0, 0, 0, 0])
    np.testing.assert_array_equal(out[:, column["rested"]],
                                  [0 + 1 >= interval, 1 + 1 >= interval, 1, 3 + 1 >= interval, 1])
    np.testing.assert_allclose(out[:, column["since_release"]],
                               np.minimum([0, 1, 9, 3, 9], interval) / interval, rtol=1e-6)
    np.testing.assert_allclose(out[:, column["potential"]], [0, 0, 0, 0, (span - 1) / span],
                               rtol=1e-6)  # fmt: skip
    np.testing.assert_array_equal(out[:, column["is_target"]], [0, 0, 1, 0, 0])
    np.testing.assert_allclose(out[:, column["prior"]], target_prior(n, target), rtol=1e-6)
    np.testing.assert_array_equal(out[:, column["rule_choice"]], [0, 0, 0, 1, 0])
    # The step's facts, the same on every row: steps 4..9 ahead (4 and 9 wanted), ...
    expected = [1, 0, 0, 0, 0, 1][:AHEAD_STEPS] + [
        step / 59, 0.0, 0.0, 0.3, 0.7, (0.7 + 0.4 + 0.1 + 0.3) / 4, 0.0]  # fmt: skip
    for row in out:
        np.testing.assert_allclose(row[len(NEURON_FEATURES):], expected, rtol=1e-6)


def test_it_acts_legally_and_alone_as_in_a_batch():
    contexts = ContextSet.generate(4, n_neurons=9, seed=6)
    controller = BeliefPolicyController(BeliefKernel(random_belief(2)), random_net(2))
    batched = evaluate_policy(contexts, controller)
    env = NeuronControlEnv(contexts=contexts)
    for index in range(4):
        actions, total = play_episode(env, BeliefPolicyController(
            BeliefKernel(random_belief(2)), random_net(2)), index, seed=0)  # fmt: skip
        assert total == pytest.approx(batched.returns[index])
        observation, info = env.reset(seed=0, options={"context": index})
        for action in actions:  # every action was legal where it was taken
            assert info["action_mask"][action + 1]
            observation, _, _, _, info = env.step(action)


def test_a_saved_policy_plays_as_the_one_in_memory(tmp_path):
    belief, net = random_belief(7), random_net(7, width=12)
    save_belief_policy(belief, net, tmp_path / "policy.pt")
    contexts = ContextSet.generate(2, n_neurons=7, seed=3)
    env = NeuronControlEnv(contexts=contexts)
    loaded = spikectl.load_controller(tmp_path / "policy.pt", env=env)
    assert isinstance(loaded, BeliefPolicyController)
    memory = BeliefPolicyController(BeliefKernel(belief), net)
    for index in range(2):
        (actions, total), (expected, expected_total) = (
            play_episode(env, loaded, index), play_episode(env, memory, index))
        np.testing.assert_array_equal(actions, expected)
        assert total == expected_total
    # The belief alone is still the amortised controller's file.
    torch.save(belief.state_dict(), tmp_path / "belief.pt")
    assert type(spikectl.load_controller(tmp_path / "belief.pt")) is AmortisedController


def bad_policy_files(tmp_path) -> dict[str, str]:
    belief, net = random_belief(1), random_net(1, width=8)
    whole = {f"belief.{k}": v for k, v in belief.state_dict().items()}
    whole.update({f"policy.{k}": v for k, v in net.state_dict().items()})
    torch.save({k: v for k, v in whole.items() if k.startswith("policy.")},
               tmp_path / "no-belief.pt")  # fmt: skip
    wider = dict(whole)
    wider["policy.neuron.0.weight"] = torch.zeros(8, N_POLICY_FEATURES + 2)
    torch.save(wider, tmp_path / "features.pt")
    missing = dict(whole)
    del missing["policy.stimulate.bias"]
    torch.save(missing, tmp_path / "missing.pt")
    bad = {k: v.clone() for k, v in whole.items()}
    bad["policy.nothing.2.bias"][0] = float("inf")
    torch.save(bad, tmp_path / "inf.pt")
    return {"no-belief.pt": "needs both", "features.pt": "does not hold a belief policy",
            "missing.pt": "do not fit", "inf.pt": "NaN or infinite"}  # fmt: skip


def test_bad_policy_files_are_refused_in_one_line(tmp_path, capsys):
    for name, words in bad_policy_files(tmp_path).items():
        with pytest.raises(BeliefWeightsError) as caught:
            load_belief_policy(tmp_path / name)
        message = str(caught.value)
        assert words in message and "\n" not in message, message
        code, _, err = run_main(["realtime", str(tmp_path / name), "--episodes", "1",
                                 "--n-neurons", "6"], capsys)  # fmt: skip
        assert code == 2 and words in err and err.strip().count("\n") == 0, err
