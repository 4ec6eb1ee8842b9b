"""The compiled policy (spikectl.agents.compiled, docs/realtime.md): it picks the PyTorch
network's greedy actions, its file round-trips and refuses what it cannot use, and it
loads and acts without PyTorch."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import torch

from spikectl.agents import greedy_action, make_agent, observation_batch
from spikectl.agents.compiled import (
    FORMAT_VERSION,
    CompiledPolicy,
    PolicyFileError,
    export_policy,
)
from spikectl.agents.policy_kernel import _tanh
from spikectl.contexts import ContextSet, make_splits
from spikectl.envs.env import NeuronControlEnv
from spikectl.training.presets import QUICK, SMOKE

ROOT = Path(__file__).resolve().parent.parent
QUICK_SIZES = QUICK.agent.sizes
SMOKE_SIZES = SMOKE.agent.sizes
NEAR_TIE = 1e-5
"""Two legal Q-values closer than this are a near-tie: float rounding may order them
either way, so the argmax may differ there without either forward being wrong."""
Q_TOLERANCE = 1e-5


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the other engineer's runs share the 2 cores
    yield
    torch.set_num_threads(threads)


@dataclass
class Agreement:
    """How the compiled policy compared with the network over a set of episodes."""

    steps: int = 0
    flips: int = 0
    """Steps whose compiled argmax differed from the network's."""
    near_ties: int = 0
    """Steps whose best two legal Q-values (network) were closer than NEAR_TIE."""
    flips_off_ties: int = 0
    """Flips where the network's best action led by at least NEAR_TIE: real errors."""
    exact_ties: int = 0
    """Near-ties whose best two legal Q-values were equal: symmetric neurons (same
    inputs, same history) get the same Q-value in exact arithmetic."""
    largest_flip_gap: float = 0.0
    """The largest Q(network's action) - Q(compiled action) among flips, in the network."""
    max_q_difference: float = 0.0
    actions: int = 0
    """How many different actions the network chose (a test that sees only "do
    nothing" would prove little)."""

    def __str__(self) -> str:
        return (
            f"{self.steps} steps: {self.flips} flips ({self.flips_off_ties} off near-ties), "
            f"{self.near_ties} near-ties ({self.exact_ties} exact), largest gap at a flip "
            f"{self.largest_flip_gap:.1e}, max |dQ| {self.max_q_difference:.1e}, "
            f"{self.actions} distinct actions"
        )


def compare(
    network: torch.nn.Module, contexts: ContextSet, driver: str = "greedy", seed: int = 0
) -> Agreement:
    """Play one episode on every context, driven by the network's greedy action
    (``driver="greedy"``) or random legal actions (``"random"``: states greedy play
    never reaches), comparing the compiled policy with the network at every step."""
    network.eval()
    policy = CompiledPolicy.from_network(network)
    env = NeuronControlEnv(contexts=contexts)
    rng = np.random.default_rng(seed)
    result, chosen = Agreement(), set()
    for index in range(len(contexts)):
        observation, info = env.reset(seed=seed + index, options={"context": index})
        state, done = None, False
        while not done:
            with torch.no_grad():
                q, state = network.step(observation_batch([observation]), state)  # [1, n+1]
            mask = info["action_mask"].astype(bool)  # int8 in the info: index with bool
            action = int(greedy_action(q, torch.as_tensor(mask)[None])[0])
            compiled = policy.act(observation, info)
            legal_q = np.sort(q[0].numpy()[mask])[::-1]
            near_tie = legal_q.size > 1 and legal_q[0] - legal_q[1] < NEAR_TIE
            result.steps += 1
            result.near_ties += near_tie
            result.flips += compiled != action
            result.flips_off_ties += compiled != action and not near_tie
            result.exact_ties += near_tie and legal_q[0] == legal_q[1]
            if compiled != action:
                gap = float(q[0, action + 1] - q[0, compiled + 1])
                result.largest_flip_gap = max(result.largest_flip_gap, gap)
            result.max_q_difference = max(
                result.max_q_difference, float(np.abs(policy.last_q - q[0].numpy()).max())
            )
            chosen.add(action)
            if driver == "random":
                action = int(rng.choice(np.flatnonzero(mask)) - 1)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
    result.actions = len(chosen)
    return result


def network(arch: str, n: int, episode_length: int, sizes, seed: int = 0) -> torch.nn.Module:
    torch.manual_seed(seed)
    return make_agent(arch, n, episode_length, sizes).eval()


def test_set(n: int, episode_length: int, n_test: int) -> ContextSet:
    return make_splits(n_train=1, n_test=n_test, n_neurons=n, episode_length=episode_length)[1]


test_set.__test__ = False  # a helper, not a test


def check(agreement: Agreement) -> None:
    print(agreement)  # the counts docs/realtime.md reports (pytest -s shows them)
    assert agreement.flips_off_ties == 0, agreement
    assert agreement.max_q_difference < Q_TOLERANCE, agreement


@pytest.mark.parametrize(
    "label, arch, sizes, n, episode_length, n_test, driver",
    [
        pytest.param(
            "tdrqn quick n=8", "tdrqn", QUICK_SIZES, 8, 60, 20, "greedy", marks=pytest.mark.slow
        ),  # 23 s; smoke sizes play greedily below
        ("tdrqn quick n=8 random play", "tdrqn", QUICK_SIZES, 8, 60, 20, "random"),
        ("tdrqn smoke n=5", "tdrqn", SMOKE_SIZES, 5, 20, 30, "greedy"),
        ("tdrqn smoke n=5 random play", "tdrqn", SMOKE_SIZES, 5, 20, 30, "random"),
        ("tdrqn paper sizes n=8", "tdrqn", None, 8, 60, 6, "random"),
        ("ddrqn quick n=8", "ddrqn", QUICK_SIZES, 8, 60, 6, "random"),
    ],
)
def test_compiled_policy_picks_the_networks_actions(
    label, arch, sizes, n, episode_length, n_test, driver
):
    agreement = compare(
        network(arch, n, episode_length, sizes), test_set(n, episode_length, n_test), driver
    )
    check(agreement)


@pytest.mark.parametrize(
    "options",
    [
        dict(do_nothing_head="dueling"),
        dict(inputs=()),
        dict(inputs=("target",), attn_heads=2),
        dict(lstm_hidden=24),  # lstm_hidden != attn_width: the projection
        dict(inputs=("target", "others-spiking")),
        dict(inputs=("others-spiking",)),
        dict(inputs=("target", "target-voltage", "others-spiking", "proximity")),
    ],
)
def test_every_option_of_the_forward_matches(options):
    sizes = replace(SMOKE_SIZES, **options)
    check(compare(network("tdrqn", 5, 20, sizes), test_set(5, 20, 6), "random"))


def test_export_refuses_inputs_the_forward_does_not_compute():
    # The compiled forward computes its four features in one order; another order is
    # refused at export, naming what it computes (a feature it does not know, too:
    # tests/test_agent_inputs.py).
    net = network("tdrqn", 5, 20, replace(SMOKE_SIZES, inputs=("proximity", "target")))
    with pytest.raises(ValueError, match="computes the input features target, "
                                         "target-voltage, others-spiking, proximity"):  # fmt: skip
        CompiledPolicy.from_network(net)


def test_a_network_runs_on_another_n_as_the_network_does():
    # Built for 8 neurons, played on 12: the per-neuron networks run on any n.
    check(compare(network("tdrqn", 8, 60, QUICK_SIZES), test_set(12, 60, 3), "random"))


def test_a_trained_network_matches():
    from spikectl.training.loaders import load_agent

    run_dir = ROOT / "tests" / "data" / "format2-smoke-run"
    trained = load_agent(run_dir, model="best")
    contexts = ContextSet.load(run_dir / "test_contexts.npz")
    check(compare(trained, contexts, "greedy"))
    check(compare(trained, contexts, "random"))


@pytest.mark.slow
@pytest.mark.parametrize("n", [8, 32])
def test_compiled_policy_picks_the_networks_actions_on_a_whole_test_set(n):
    # 100 test contexts, greedy play, quick sizes: the check docs/realtime.md reports.
    check(compare(network("tdrqn", 8, 60, QUICK_SIZES), test_set(n, 60, 100), "greedy"))


def test_save_and_load_round_trip(tmp_path):
    net = network("tdrqn", 5, 20, SMOKE_SIZES)
    path = export_policy(net, tmp_path / "policy.npz")
    assert path == tmp_path / "policy.npz"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy.npz"]  # no temporary left
    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["metadata"]))
        assert header["format_version"] == FORMAT_VERSION
        assert header["architecture"] == "tdrqn"
        for name, tensor in net.state_dict().items():
            assert data[name].dtype == np.float32
            np.testing.assert_array_equal(data[name], tensor.numpy())
    loaded = CompiledPolicy.load(path)
    direct = CompiledPolicy.from_network(net)
    assert loaded.spec == direct.spec
    contexts = test_set(5, 20, 2)
    env = NeuronControlEnv(contexts=contexts)
    observation, info = env.reset(seed=0, options={"context": 1})
    for _ in range(20):
        action = loaded.act(observation, info)
        assert direct.act(observation, info) == action
        np.testing.assert_array_equal(loaded.last_q, direct.last_q)
        observation, _, terminated, _, info = env.step(action)
        if terminated:
            break


def test_loading_and_acting_need_no_torch(tmp_path):
    path = export_policy(network("tdrqn", 5, 20, SMOKE_SIZES), tmp_path / "policy.npz")
    code = (
        "import sys, numpy as np\n"
        "from spikectl.agents.compiled import CompiledPolicy\n"
        f"policy = CompiledPolicy.load({str(path)!r})\n"
        "observation = dict(voltage=np.full(5, -70.0, np.float32), target=1,\n"
        "                   pattern=np.zeros(20, np.int8), step=0, last_action=-1)\n"
        "mask = np.ones(6, bool); mask[2] = False\n"
        "action = policy.act(observation, {'action_mask': mask})\n"
        "assert -1 <= action < 5 and action != 1, action\n"
        "print(sorted(m for m in ('torch', 'spikectl.training') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_architectures_it_cannot_compile_are_refused_by_name(tmp_path):
    for arch in ("drqn", "dmdrqn"):
        with pytest.raises(ValueError, match="supported architectures: tdrqn, ddrqn"):
            export_policy(make_agent(arch, 5, 20, SMOKE_SIZES), tmp_path / "policy.npz")
    assert not list(tmp_path.iterdir())


def rewrite(path: Path, header_changes=None, drop=None, reshape=None) -> Path:
    """A copy of a policy file with its header or weights altered."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    header = json.loads(str(arrays["metadata"]))
    header.update(header_changes or {})
    arrays["metadata"] = np.array(json.dumps(header))
    if drop:
        del arrays[drop]
    if reshape:
        arrays[reshape] = arrays[reshape][:-1]
    out = path.with_name("altered.npz")
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    out.write_bytes(buffer.getvalue())
    return out


@pytest.fixture
def policy_file(tmp_path) -> Path:
    return export_policy(network("tdrqn", 5, 20, SMOKE_SIZES), tmp_path / "policy.npz")


def test_unreadable_files_are_refused_with_the_problem(tmp_path, policy_file):
    with pytest.raises(FileNotFoundError, match="not found"):
        CompiledPolicy.load(tmp_path / "missing.npz")
    with pytest.raises(PolicyFileError, match="is a folder"):
        CompiledPolicy.load(tmp_path)
    fifo = tmp_path / "fifo.npz"
    os.mkfifo(fifo)
    with pytest.raises(PolicyFileError, match="not a regular file"):
        CompiledPolicy.load(fifo)  # refused at once, never a hang
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file")
    with pytest.raises(PolicyFileError, match="not a readable compiled policy"):
        CompiledPolicy.load(garbage)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, weights=np.zeros(3))
    with pytest.raises(PolicyFileError, match="no 'metadata' entry"):
        CompiledPolicy.load(foreign)
    with pytest.raises(PolicyFileError, match="is a context set file .*; a compiled policy is"):
        CompiledPolicy.load(rewrite(policy_file, {"format": "spikectl.ContextSet"}))
    with pytest.raises(PolicyFileError, match="not a compiled policy"):
        CompiledPolicy.load(rewrite(policy_file, {"format": "spikectl.Other"}))


def test_other_versions_and_architectures_are_refused_by_name(policy_file):
    with pytest.raises(PolicyFileError, match="format version 99; this spikectl reads version 2"):
        CompiledPolicy.load(rewrite(policy_file, {"format_version": 99}))
    with pytest.raises(PolicyFileError, match="architecture 'drqn'; supported: tdrqn, ddrqn"):
        CompiledPolicy.load(rewrite(policy_file, {"architecture": "drqn"}))


def test_files_written_before_the_others_spiking_input_still_load(policy_file):
    # Version-1 files made before AgentSizes.others_spiking_in_input existed lack the key.
    with np.load(policy_file, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    header = json.loads(str(arrays["metadata"]))
    assert header.pop("others_spiking_in_input") is False
    arrays["metadata"] = np.array(json.dumps(header))
    older = policy_file.with_name("older.npz")
    np.savez(older, **arrays)
    assert CompiledPolicy.load(older).spec == CompiledPolicy.load(policy_file).spec
    with pytest.raises(PolicyFileError, match="others_spiking_in_input is 1"):
        CompiledPolicy.load(rewrite(policy_file, {"others_spiking_in_input": 1}))


def test_weights_that_do_not_match_the_header_are_named(policy_file):
    with pytest.raises(PolicyFileError, match=r"lack \['head.value.0.bias'\]"):
        CompiledPolicy.load(rewrite(policy_file, drop="head.value.0.bias"))
    with pytest.raises(PolicyFileError, match=r"header does not match .* pattern_embed 4 \(the "):
        CompiledPolicy.load(rewrite(policy_file, reshape="context.pattern.0.weight"))
    # A header that says 3 layers where the weights hold 2.
    with pytest.raises(PolicyFileError, match=r"attn_layers 3 \(the weights: 2\)$"):
        CompiledPolicy.load(rewrite(policy_file, {"attn_layers": 3}))
    with pytest.raises(PolicyFileError, match=r"lacks \['lstm_hidden'\]"):
        altered = rewrite(policy_file)
        with np.load(altered) as data:
            arrays = {name: data[name] for name in data.files}
        header = json.loads(str(arrays["metadata"]))
        del header["lstm_hidden"]
        arrays["metadata"] = np.array(json.dumps(header))
        np.savez(altered, **arrays)
        CompiledPolicy.load(altered)


def rechecksummed(path: Path, changes: dict) -> Path:
    """A copy of a policy file with its header changed and its checksum made again, as a
    hand edit that knows the format would: only the header's agreement with the weights
    can then tell."""
    from spikectl.agents.policy_file import policy_checksum
    from spikectl.agents.policy_header import parse_header

    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    header = {**json.loads(str(arrays.pop("metadata"))), **changes}
    header["checksum"] = policy_checksum(parse_header("x", np.array(json.dumps(header))), arrays)
    out = path.with_name("rechecksummed.npz")
    np.savez(out, metadata=np.array(json.dumps(header)), **arrays)
    return out


@pytest.mark.parametrize("changes, named", [
    ({"lstm_hidden": 8}, "lstm_hidden 8 (the weights: 16)"),
    ({"attn_layers": 1}, "attn_layers 1 (the weights: 2)"),
    ({"attn_width": 32, "attn_heads": 1}, "attn_width 32 (the weights: 16)"),
    ({"architecture": "ddrqn"}, "architecture ddrqn (the weights: tdrqn)"),
    ({"head_hidden": [32, 32]}, "head_hidden [32, 32] (the weights: [32])"),
    ({"value_hidden": [8]}, "value_hidden [8] (the weights: [16])"),
    ({"episode_length": 30}, "episode_length 30 (the weights: 20)"),
    ({"target_in_input": False}, "input features 2 (the weights: 3)"),
])  # fmt: skip
def test_a_header_is_cross_checked_against_its_weights_in_one_line(policy_file, changes, named):
    """Every header field the weights' shapes imply is compared with them, even where the
    checksum was made again: one line naming the field and both values, not a list of
    every weight's shape."""
    with pytest.raises(PolicyFileError) as caught:
        CompiledPolicy.load(rechecksummed(policy_file, changes))
    message = str(caught.value)
    assert message.endswith(f"its header does not match its weights: {named}"), message
    assert len(message) < 300 and "\n" not in message


def test_header_values_and_weights_are_checked(policy_file):
    for changes, message in (
        ({"lstm_hidden": "16"}, "lstm_hidden is '16'"),
        ({"head_hidden": [32, 0]}, "head_hidden is"),
        ({"target_in_input": 1}, "target_in_input is 1"),
        ({"do_nothing_head": "mean"}, "do_nothing_head 'mean'"),
        ({"attn_heads": 3}, "must divide attn_width"),
    ):
        with pytest.raises(PolicyFileError, match=message):
            CompiledPolicy.load(rewrite(policy_file, changes))
    with np.load(policy_file) as data:
        arrays = {name: data[name] for name in data.files}
    arrays["head.value.0.weight"][0, 0] = np.nan
    np.savez(policy_file, **arrays)
    with pytest.raises(PolicyFileError, match=r"\['head.value.0.weight'\] hold NaN"):
        CompiledPolicy.load(policy_file)


def test_act_checks_its_inputs(policy_file):
    policy = CompiledPolicy.load(policy_file)
    observation = dict(voltage=np.full(5, -70.0, np.float32), target=1,
                       pattern=np.zeros(20, np.int8), step=0, last_action=-1)  # fmt: skip
    mask = np.ones(6, bool)
    with pytest.raises(ValueError, match=r"pattern \[20\]"):
        policy.act({**observation, "pattern": np.zeros(19, np.int8)}, {"action_mask": mask})
    with pytest.raises(ValueError, match="out of range"):
        policy.act({**observation, "target": 5}, {"action_mask": mask})
    with pytest.raises(ValueError, match="allows no action"):
        policy.act(observation, {"action_mask": np.zeros(6, bool)})
    policy.reset()
    with pytest.raises(ValueError, match="from step 0"):
        policy.act({**observation, "step": 3}, {"action_mask": mask})
    policy.act(observation, {"action_mask": mask})
    with pytest.raises(ValueError, match="started with n = 5"):
        policy.act(
            {**observation, "voltage": np.full(6, -70.0, np.float32), "step": 1},
            {"action_mask": np.ones(7, bool)},
        )
    # The mask is obeyed: every action but one illegal leaves that one.
    only = np.zeros(6, bool)
    only[4] = True
    assert policy.act({**observation, "step": 0}, {"action_mask": only}) == 3


def test_the_fast_tanh_is_within_4e7_of_tanh():
    x = np.linspace(-12.0, 12.0, 20_001).astype(np.float32)
    approx = np.array([_tanh(v) for v in x], dtype=np.float64)
    assert np.abs(approx - np.tanh(x.astype(np.float64))).max() < 4e-7
