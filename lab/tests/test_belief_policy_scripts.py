"""The belief policy's DAgger scripts (lab/results/belief-policy): the collected labels
are the expert's own actions where the expert acts, replayed features are the ones the
controller computes while it acts, and the fit learns a labelling rule it can express."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from lab.scripts import load_script
from spikectl import ContextSet, NeuronControlEnv
from spikectl.agents.amortised_belief import AmortisedBelief
from spikectl.agents.amortised_controller import AmortisedController
from spikectl.agents.amortised_kernel import BeliefKernel
from spikectl.agents.belief_policy import BeliefPolicyController, BeliefPolicyNet, PolicyKernel

SCRIPTS = Path(__file__).resolve().parents[1] / "results" / "belief-policy"


def script(name: str):
    return load_script("belief-policy", name)


def belief(seed: int) -> AmortisedBelief:
    torch.manual_seed(seed)
    return AmortisedBelief(8, 4, 1).eval()  # an untrained belief is the prior


class Recording(BeliefPolicyController):
    """A belief policy that keeps every step's features as it acts."""

    def __init__(self, *arguments) -> None:
        super().__init__(*arguments)
        self.seen: list[np.ndarray] = []

    def decide(self, pattern, step, mask) -> int:
        action = super().decide(pattern, step, mask)
        self.seen.append(self.last_features.copy())
        return action


def test_expert_labels_and_replayed_features(monkeypatch):
    collect, train = script("collect"), script("train")
    contexts = ContextSet.generate(3, n_neurons=6, seed=4)
    monkeypatch.setattr(collect, "training_networks", lambda n, count: contexts)
    data = collect.collect(6, 2, 1, None, 0.0, 0)
    np.testing.assert_array_equal(data["taken"], data["label"])  # the expert acted
    assert (data["label"] >= 0).any()
    # Replaying an episode gives the features the controller computed while acting on it.
    kernel, net = BeliefKernel(belief(1)), BeliefPolicyNet(8)
    acting = Recording(kernel, net)
    env = NeuronControlEnv(contexts=contexts)
    record = {key: [] for key in ("voltage", "last_action", "mask", "step", "label")}
    observation, info = env.reset(seed=2, options={"context": 2})
    pattern, target = observation["pattern"], observation["target"]
    for _ in range(env.episode_length):
        for key in ("voltage", "last_action", "step"):
            record[key].append(observation[key])
        record["mask"].append(info["action_mask"])
        action = acting.act(observation, info)
        record["label"].append(action)
        observation, _, _, _, info = env.step(action)
    replayed = {key: np.asarray(value)[None] for key, value in record.items()}
    replayed.update(pattern=np.asarray(pattern)[None], target=np.array([target]))
    features, masks, labels = train.replay(replayed, BeliefKernel(belief(1)))
    np.testing.assert_array_equal(features, np.stack(acting.seen))
    np.testing.assert_array_equal(labels, np.asarray(record["label"]) + 1)


def test_the_fit_learns_the_amortised_rule():
    """Labels from the amortised controller's fixed rule, which reads only what the
    policy's features hold: the fitted policy agrees with it on most decisions."""
    train = script("train")
    contexts = ContextSet.generate(24, n_neurons=8, seed=9)
    env, kernel = NeuronControlEnv(contexts=contexts), BeliefKernel(belief(2))
    rule, recorder = AmortisedController(kernel), BeliefPolicyController(kernel, None)
    features, masks, labels = [], [], []
    for index in range(24):
        observation, info = env.reset(seed=index, options={"context": index})
        rule.reset()
        recorder.reset()
        for _ in range(env.episode_length):
            action = rule.act(observation, info)
            recorder.probabilities, recorder.tracker = rule.probabilities, rule.tracker
            legal = np.asarray(info["action_mask"], dtype=bool)
            features.append(train.policy_features(
                rule.probabilities, legal[1:], rule.can_land(legal[1:]), rule.tracker,
                np.asarray(observation["pattern"], dtype=bool), int(observation["step"]),
                rule.params, action))  # fmt: skip
            masks.append(legal)
            labels.append(action + 1)
            observation, _, _, _, info = env.step(action)
    data = (np.stack(features), np.stack(masks), np.array(labels))
    net, rows = train.fit([data], epochs=25, seed=0, width=32, batch=64, learning_rate=3e-3)
    assert rows[-1]["loss"] < rows[0]["loss"]
    kernel = PolicyKernel(net)
    agree = [int(np.argmax(np.where(m, kernel.scores(f), -np.inf))) == y
             for f, m, y in zip(*data, strict=True)]  # fmt: skip
    majority = np.mean(data[2] == 0)  # doing nothing: the commonest label
    assert np.mean(agree) > max(0.9, majority + 0.05), (np.mean(agree), majority)
