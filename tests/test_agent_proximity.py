"""The target's proximity on the generator's line as a per-neuron input (the
``proximity`` feature of ``AgentSizes.inputs``, docs/agents.md): its values by hand,
equivariance under a joint relabelling of neurons and positions (and not under a relabelling that
leaves the positions behind), the ``position`` key's checks, and the compiled policy."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from test_agents import EQUIVARIANT, permute_neurons, random_obs, small_agent

from spikectl.agents import make_agent, observation_batch
from spikectl.agents.compiled import CompiledPolicy, PolicyFileError, export_policy
from spikectl.agents.features import target_proximity
from spikectl.agents.inputs import per_neuron_inputs
from spikectl.training.presets import SMOKE

PROXIMITY = ("target", "proximity")
"""The default input and the proximity after it."""


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_proximity_by_hand() -> None:
    # Neurons 0..15 on the line, target 10: distance 0 → 0 (the target itself), 1-4 →
    # 0.3, 5-8 → 0.2, 9-12 → 0.1, beyond → 0.01 (the generator's bands).
    proximity = target_proximity(torch.arange(16.0)[None], torch.tensor([10]))
    expected = [0.1, 0.1, 0.2, 0.2, 0.2, 0.2, 0.3, 0.3, 0.3, 0.3, 0.0,
                0.3, 0.3, 0.3, 0.3, 0.2]  # fmt: skip
    torch.testing.assert_close(proximity, torch.tensor([expected]))
    # Target 0 of 32: neuron 12 is in the last band, 13 beyond it.
    far = target_proximity(torch.arange(32.0), torch.tensor(0))
    assert far[12].item() == pytest.approx(0.1) and far[13].item() == pytest.approx(0.01)
    # Positions from the observation where it holds them: the feature follows them.
    obs = dict(voltage=torch.full((1, 3), -70.0), last_action=torch.tensor([-1]),
               target=torch.tensor([0]), position=torch.tensor([[20.0, 27.0, 5.0]]))  # fmt: skip
    x = per_neuron_inputs(obs, ("proximity",), v_rest_mV=-70.0, v_threshold_mV=-50.0,
                          dtype=torch.float32)  # fmt: skip
    torch.testing.assert_close(x[0, :, -1], torch.tensor([0.0, 0.2, 0.01]))
    assert small_agent("ddrqn", 4, inputs=PROXIMITY).lstm.lstm.input_size == 4


def with_positions(obs: dict, perm: torch.Tensor | None = None) -> dict:
    """``obs`` relabelled by ``perm`` (new neuron k is old perm[k]), each neuron keeping
    its position on the line (the ``position`` key)."""
    n = obs["voltage"].shape[-1]
    position = torch.arange(n, dtype=obs["voltage"].dtype).expand(obs["voltage"].shape)
    if perm is None:
        return {**obs, "position": position}
    return {**permute_neurons(obs, perm), "position": position[..., perm]}


@pytest.mark.parametrize("name", EQUIVARIANT)
def test_equivariant_under_a_joint_relabelling_of_neurons_and_positions(name: str) -> None:
    B, T, n = 3, 9, 16
    net = small_agent(name, n, inputs=PROXIMITY).double()
    obs = random_obs(B, T, n, seed=1)
    q, _ = net(obs)
    q_told, _ = net(with_positions(obs))  # the default positions are the indices
    torch.testing.assert_close(q_told, q, atol=0, rtol=0)
    g = torch.Generator().manual_seed(7)
    moved = 0.0
    for _ in range(3):
        perm = torch.randperm(n, generator=g)
        q_p, _ = net(with_positions(obs, perm))
        torch.testing.assert_close(q_p[..., 0], q[..., 0], atol=1e-10, rtol=1e-10)
        torch.testing.assert_close(q_p[..., 1:], q[..., 1:][..., perm], atol=1e-10, rtol=1e-10)
        # Relabelled with the positions left at the indices, the network sees another
        # geometry: its Q-values are not the permuted ones.
        q_left, _ = net(permute_neurons(obs, perm))
        moved = max(moved, float((q_left[..., 1:] - q[..., 1:][..., perm]).abs().max().detach()))
    assert moved > 1e-4


def test_bad_positions_and_architectures_are_refused_by_name() -> None:
    net = small_agent("tdrqn", 5, inputs=PROXIMITY)
    obs = random_obs(2, 3, 5)
    with pytest.raises(ValueError, match=r"obs\['position'\] must have the shape of"):
        net({**obs, "position": torch.zeros(2, 3, 4)})
    with pytest.raises(ValueError, match=r"obs\['position'\] must be finite"):
        net({**obs, "position": torch.full((2, 3, 5), float("nan"))})
    with pytest.raises(TypeError, match=r"obs\['position'\] must be a real tensor"):
        net({**obs, "position": [0, 1, 2, 3, 4]})
    with pytest.raises(ValueError, match="AgentSizes.inputs: 'proximity' is read by the "
                                         "per-neuron networks.*not by drqn"):  # fmt: skip
        small_agent("drqn", 5, inputs=PROXIMITY)
    small_agent("drqn", 5, inputs=("target", "target-voltage"))  # older features: ignored


def episode_observations(n: int, N: int, seed: int):
    rng = np.random.default_rng(seed)
    pattern = (rng.random(N) < 0.3).astype(np.int8)
    for step in range(N):
        yield dict(voltage=(-72.0 + 25.0 * rng.random(n)).astype(np.float32), target=2,
                   pattern=pattern, step=step, last_action=int(rng.integers(-1, n)))  # fmt: skip


@pytest.mark.parametrize("arch", ["tdrqn", "ddrqn"])
def test_the_compiled_policy_computes_it_as_the_network_does(arch, tmp_path) -> None:
    torch.manual_seed(0)
    sizes = replace(SMOKE.agent.sizes, inputs=PROXIMITY)
    net = make_agent(arch, 16, 20, sizes).eval()
    policy = CompiledPolicy.load(export_policy(net, tmp_path / "policy.npz"))
    assert policy.spec.proximity_in_input and policy.spec.input_features == 4
    assert policy.spec.inputs == PROXIMITY
    mask = np.ones(17, dtype=bool)
    positions = np.random.default_rng(1).permutation(16).astype(np.float32)
    for given in (None, positions):
        state, policy_q = None, []
        for observation in episode_observations(16, 20, seed=2):
            if given is not None:
                observation["position"] = given
            with torch.no_grad():
                q, state = net.step(observation_batch([observation]), state)
            policy.act(observation, {"action_mask": mask})
            policy_q.append(np.abs(policy.last_q - q[0].numpy()).max())
        assert max(policy_q) < 1e-5
    with pytest.raises(ValueError, match=r"observation\['position'\] must hold 16 finite"):
        policy.act({**observation, "step": 0, "position": positions[:3]}, {"action_mask": mask})


def test_files_written_before_the_proximity_input_still_load(tmp_path) -> None:
    # Files written before the field existed carry a checksum over a header without it.
    import hashlib
    from dataclasses import asdict

    torch.manual_seed(0)
    path = export_policy(make_agent("tdrqn", 5, 20, SMOKE.agent.sizes), tmp_path / "new.npz")
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    header = json.loads(str(arrays["metadata"]))
    spec = CompiledPolicy.load(path).spec
    old_header = asdict(spec)
    del old_header["proximity_in_input"]
    digest = hashlib.sha256(json.dumps(old_header, sort_keys=True).encode())
    weights = {name: array for name, array in arrays.items() if name != "metadata"}
    for name in sorted(weights):
        array = np.ascontiguousarray(weights[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    del header["proximity_in_input"]
    header["checksum"] = digest.hexdigest()
    arrays["metadata"] = np.array(json.dumps(header))
    older = tmp_path / "older.npz"
    np.savez(older, **arrays)
    assert CompiledPolicy.load(older).spec == spec
    header["proximity_in_input"] = True  # a header changed over the same weights
    arrays["metadata"] = np.array(json.dumps(header))
    np.savez(older, **arrays)
    with pytest.raises(PolicyFileError):
        CompiledPolicy.load(older)
