"""The controller on the amortised belief (issue 61, item 2): its NumPy step is the
PyTorch belief's, its feature rows are ``belief_features``' step by step, it acts
legally and deterministically, relabelling neurons relabels what it does, a belief certain
of the truth plays the witness of a hand-built network, and a bad weights file is one
line (exit 2 on the command line)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import run_main

import spikectl
from spikectl import ContextSet, make_context
from spikectl.agents.amortised_belief import N_FEATURES, AmortisedBelief, belief_features
from spikectl.agents.amortised_controller import (
    AmortisedController,
    BeliefWeightsError,
    choose_action,
    load_belief,
)
from spikectl.agents.amortised_kernel import BeliefFeatureTracker, BeliefKernel, target_prior
from spikectl.envs.controller import play_episode
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import evaluate_policy
from spikectl.neuron.params import NeuronParams
from spikectl.training.belief_episodes import belief_batch


def random_belief(seed: int, width: int = 16, mix_layers: int = 1) -> AmortisedBelief:
    """A belief with every weight drawn (the head too: an untrained one is the prior)."""
    model = AmortisedBelief(width, 4, mix_layers)
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.copy_(0.5 * torch.randn(parameter.shape, generator=generator))
    return model.eval()


class CertainBelief:
    """A belief that knows the target's column: logits of 0 for its class, -30 else."""

    def __init__(self, column: np.ndarray) -> None:
        self.classes = np.where(column > 0, 1, np.where(column < 0, 2, 0))

    def reset(self, prior: np.ndarray) -> None:
        pass

    def step(self, features: np.ndarray) -> np.ndarray:
        logits = np.full((self.classes.size, 3), -30.0, dtype=np.float32)
        logits[np.arange(self.classes.size), self.classes] = 0.0
        return logits


@pytest.mark.parametrize("n_neurons, mix_layers", [(8, 1), (13, 2)])
def test_the_numpy_step_and_feature_rows_equal_the_torch_belief(n_neurons, mix_layers):
    batch = belief_batch(np.random.default_rng(n_neurons), n_neurons, 1, 30)
    model = random_belief(n_neurons, mix_layers=mix_layers)
    with torch.no_grad():
        expected = model(torch.from_numpy(batch.features))[0].numpy()  # [T, n, 3]
    target = int(np.flatnonzero(batch.is_target[0])[0])
    tracker = BeliefFeatureTracker(n_neurons, target, NeuronParams())
    kernel = BeliefKernel(model)
    kernel.reset(target_prior(n_neurons, target))
    for t in range(30):
        # The environment observes float32 potentials; the features are float32 too.
        row = tracker.row(batch.voltages[0, t].astype(np.float32), int(batch.actions[0, t]))
        np.testing.assert_allclose(row, batch.features[0, t], atol=1e-5)
        np.testing.assert_allclose(kernel.step(row), expected[t], atol=1e-4)


def test_the_tracker_reads_a_hand_computed_lone_release():
    # 0 -> 2 excitatory: 0 stimulated at step 0 releases; at step 1 the target shows +1.
    weights = np.zeros((1, 3, 3), dtype=np.int8)
    weights[0, 0, 2] = 1
    voltages, spikes = spikectl.simulate(weights, [0, -1, -1])
    tracker = BeliefFeatureTracker(3, 2, NeuronParams())
    rows = [tracker.row(voltages[0, t], a) for t, a in enumerate([0, -1, -1])]
    full = belief_features(voltages, spikes, np.array([[0, -1, -1]]), np.array([2]))[0]
    np.testing.assert_array_equal(np.stack(rows), full)
    assert rows[1][0, 8] == pytest.approx(1.0)  # released_times_target_residual of neuron 0


def test_relabelling_the_neurons_relabels_the_belief_and_the_choice():
    rng = np.random.default_rng(3)
    kernel = BeliefKernel(random_belief(1))
    features = rng.normal(size=(4, 9, N_FEATURES)).astype(np.float32)
    prior = rng.uniform(0.01, 0.3, size=9)
    order = rng.permutation(9)
    kernel.reset(prior)
    plain = [kernel.step(row) for row in features]
    kernel.reset(prior[order])
    relabelled = [kernel.step(row[order]) for row in features]
    np.testing.assert_allclose(np.stack(relabelled), np.stack(plain)[:, order], atol=1e-5)
    excitatory = rng.uniform(size=9)  # distinct: no tie to break by index
    can_land = rng.random(9) < 0.7
    for ahead in ([True], [False, False], [False, True]):
        chosen = choose_action(excitatory, can_land, np.array(ahead))
        moved = choose_action(excitatory[order], can_land[order], np.array(ahead))
        assert moved == (-1 if chosen == -1 else int(np.flatnonzero(order == chosen)[0]))


def test_choose_action_by_hand():
    excitatory = np.array([0.1, 0.6, 0.9, 0.3])
    can_land = np.array([True, True, False, True])
    assert choose_action(excitatory, can_land, np.array([True])) == 1  # 2 cannot land
    assert choose_action(excitatory, can_land, np.array([False, True])) == -1  # wanted soon
    quiet = np.array([False] * 5)
    assert choose_action(excitatory, can_land, quiet) == -1  # 2 is an input at 0.9 >= 0.5
    assert choose_action(excitatory, can_land, quiet, probe_below=0.95) == 1  # probes 0.6
    assert choose_action(excitatory * 0.1, can_land, quiet) == 1  # 0.06: still worth one
    assert choose_action(excitatory * 0.01, can_land, quiet) == -1  # 0.006: below the floor
    assert choose_action(np.zeros(4), can_land, np.array([True])) == -1  # no input anywhere


def hand_built() -> tuple[ContextSet, np.ndarray]:
    """0 -> 7 excitatory, 1 -> 7 inhibitory, the rest unconnected; the target 7 should
    spike at steps 3 and 9: the witness stimulates 0 at steps 2 and 8."""
    weights = np.zeros((8, 8), dtype=np.int8)
    weights[0, 7], weights[1, 7] = 1, -1
    witness = np.full(12, -1)
    witness[[2, 8]] = 0
    pattern = np.zeros(12)
    pattern[[3, 9]] = 1
    context = make_context(weights, target=7, pattern=pattern, witness=witness)
    return ContextSet([context]), witness


def test_a_belief_certain_of_the_truth_plays_the_witness():
    contexts, witness = hand_built()
    env = NeuronControlEnv(contexts=contexts)
    controller = AmortisedController(CertainBelief(contexts[0].weights[:, 7]))
    actions, total = play_episode(env, controller, 0)
    np.testing.assert_array_equal(actions, witness)
    assert total == pytest.approx(1.0)
    # The prior alone (an untrained belief) tries the nearest band (3..6) first.
    untrained = AmortisedController(AmortisedBelief(16, 4, 1).eval(), probe_below=0.0)
    actions, _ = play_episode(env, untrained, 0)
    assert actions[2] == 3


def test_it_acts_legally_and_deterministically_for_a_seed():
    env = NeuronControlEnv(contexts=ContextSet.generate(3, n_neurons=10, seed=5))
    kernel = BeliefKernel(random_belief(2))
    runs = {}
    for rule, seed in (("greedy", 0), ("thompson", 4), ("thompson", 4)):
        controller = AmortisedController(kernel, rule=rule, seed=seed)
        played = []
        for context in range(3):
            controller.reset()
            observation, info = env.reset(seed=context, options={"context": context})
            for _ in range(env.episode_length):
                action = controller.act(observation, info)
                assert info["action_mask"][action + 1]  # legal: never the target
                played.append(action)
                observation, _, _, _, info = env.step(action)
        runs.setdefault((rule, seed), []).append(played)
    assert runs[("thompson", 4)][0] == runs[("thompson", 4)][1]
    assert any(action >= 0 for action in runs[("greedy", 0)][0])


def test_vector_copies_keep_their_own_belief_state():
    contexts = ContextSet.generate(4, n_neurons=8, seed=2)
    controller = AmortisedController(BeliefKernel(random_belief(3)))
    batched = evaluate_policy(contexts, controller).returns
    alone = [play_episode(NeuronControlEnv(contexts=contexts), AmortisedController(
        BeliefKernel(random_belief(3))), index, seed=0)[1] for index in range(4)]  # fmt: skip
    np.testing.assert_allclose(batched, alone)


def test_load_belief_reads_a_saved_belief_and_the_loader_plays_it(tmp_path):
    model = random_belief(4, width=8, mix_layers=2)
    torch.save(model.state_dict(), tmp_path / "belief.pt")
    loaded = load_belief(tmp_path / "belief.pt")
    assert (loaded.width, loaded.mix_layers) == (8, 2)
    env = NeuronControlEnv(contexts=ContextSet.generate(1, n_neurons=6, seed=1))
    controller = spikectl.load_controller(tmp_path / "belief.pt", env=env)
    assert isinstance(controller, AmortisedController)


def bad_files(tmp_path) -> dict[str, tuple[object, str]]:
    (tmp_path / "damaged.pt").write_bytes(b"PK\x03\x04 not really a zip")
    torch.save({"something": torch.zeros(3)}, tmp_path / "foreign.pt")
    state = random_belief(5, width=8).state_dict()
    state["encode.0.weight"] = torch.zeros(8, N_FEATURES + 1)
    torch.save(state, tmp_path / "features.pt")
    state = random_belief(5, width=8).state_dict()
    del state["head.2.bias"]
    torch.save(state, tmp_path / "missing-key.pt")
    state = random_belief(5, width=8).state_dict()
    state["head.0.bias"][0] = float("nan")
    torch.save(state, tmp_path / "nan.pt")
    return {"absent.pt": "no amortised belief weights file", "damaged.pt": "not a readable",
            "foreign.pt": "does not hold", "features.pt": "does not hold",
            "missing-key.pt": "does not fit", "nan.pt": "NaN"}  # fmt: skip


def test_bad_weight_files_are_refused_in_one_line(tmp_path):
    for name, words in bad_files(tmp_path).items():
        with pytest.raises(BeliefWeightsError) as caught:
            load_belief(tmp_path / name)
        message = str(caught.value)
        assert words in message and "\n" not in message, message


def test_the_command_line_exits_2_on_a_bad_weights_file(tmp_path, capsys):
    bad_files(tmp_path)
    for name in ("damaged.pt", "missing-key.pt"):
        code, _, err = run_main(["realtime", str(tmp_path / name), "--episodes", "1",
                                 "--n-neurons", "6"], capsys)  # fmt: skip
        assert code == 2
        assert err.strip().count("\n") == 0 and "amortised belief" in err or "readable" in err
