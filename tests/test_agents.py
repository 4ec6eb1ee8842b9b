"""Tests of the four recurrent Q-networks (spikectl.agents, docs/agents.md)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spikectl.agents import (
    AGENTS,
    AgentSizes,
    RecurrentQNetwork,
    count_parameters,
    greedy_action,
    make_agent,
    masked_q,
    observation_batch,
    parameter_counts,
    reset_state,
    shift_pattern,
)

ARCHS = sorted(AGENTS)
EQUIVARIANT = ("ddrqn", "tdrqn")
FIXED_N = ("drqn", "dmdrqn")
N_STEPS = 12  # episode length N of the small test networks

# Small sizes keep the file fast; lstm_hidden != attn_width exercises the projection.
SMALL = dict(
    lstm_hidden=12,
    target_embed=4,
    pattern_embed=4,
    ff_hidden=24,
    head_hidden=(24, 12),
    tdrqn_head_hidden=(16, 8),
    attn_width=16,
    attn_ff=32,
    value_hidden=(8,),
)

DEVICES = [
    "cpu",
    pytest.param(
        "cuda",
        marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available"),
    ),
]


def small_agent(name: str, n: int = 5, seed: int = 0, **overrides: object) -> torch.nn.Module:
    torch.manual_seed(seed)
    return make_agent(name, n, N_STEPS, **{**SMALL, **overrides})


def random_obs(
    B: int, T: int, n: int, N: int = N_STEPS, seed: int = 0, device: str = "cpu"
) -> dict[str, torch.Tensor]:
    """A sequence batch shaped like real episodes: fixed target/pattern, step = 0..T-1."""
    g = torch.Generator().manual_seed(seed)
    voltage = -70.0 + 12.0 * torch.randn(B, T, n, generator=g)  # some >= -50 (spikes)
    target = torch.randint(0, n, (B, 1), generator=g).expand(B, T)
    pattern = torch.randint(0, 2, (B, 1, N), generator=g, dtype=torch.int8).expand(B, T, N)
    step = torch.arange(T).expand(B, T)
    last_action = torch.randint(-1, n, (B, T), generator=g)
    last_action[:, 0] = -1
    obs = dict(voltage=voltage, target=target, pattern=pattern, step=step, last_action=last_action)
    return {k: v.contiguous().to(device) for k, v in obs.items()}


def at_step(obs: dict[str, torch.Tensor], t: int) -> dict[str, torch.Tensor]:
    return {k: v[:, t] for k, v in obs.items()}


def permute_neurons(obs: dict[str, torch.Tensor], perm: torch.Tensor) -> dict[str, torch.Tensor]:
    """New neuron k is old neuron perm[k]."""
    inverse = torch.argsort(perm)
    la = obs["last_action"]
    return dict(
        voltage=obs["voltage"][..., perm],
        target=inverse[obs["target"]],
        pattern=obs["pattern"],
        step=obs["step"],
        last_action=torch.where(la >= 0, inverse[la.clamp(min=0)], la),
    )


# ----------------------------------------------------------------------------
# shapes, devices, interface


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", ARCHS)
def test_shapes_and_state(name: str, device: str) -> None:
    B, T, n = 3, 7, 5
    net = small_agent(name, n).to(device)
    assert isinstance(net, RecurrentQNetwork)
    obs = random_obs(B, T, n, device=device)
    q, state = net(obs)
    assert q.shape == (B, T, n + 1) and q.device.type == device
    assert torch.isfinite(q).all()
    init = net.initial_state(B, n, device=device)
    assert isinstance(init, tuple) and all(s.device.type == device for s in init)
    assert [s.shape for s in state] == [s.shape for s in init]
    assert all(s.shape[0] == B for s in state)
    q1, state1 = net.step(at_step(obs, 0), init)
    assert q1.shape == (B, n + 1)
    assert [s.shape for s in state1] == [s.shape for s in init]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", ARCHS)
def test_step_forward_equals_sequence_forward(
    name: str, device: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Acting (eval, no grad, one step at a time) sees the training network exactly."""
    tol = 1e-5
    if device == "cuda":  # TF32 would blur the comparison, not the property
        monkeypatch.setattr(torch.backends.cudnn, "allow_tf32", False)
        monkeypatch.setattr(torch.backends.cuda.matmul, "allow_tf32", False)
        tol = 1e-4
    B, n = 3, 5
    T = N_STEPS + 1  # include the final observation (step = N, pattern all -1)
    net = small_agent(name, n).to(device)
    obs = random_obs(B, T, n, device=device)
    net.train()
    q_seq, final_seq = net(obs)  # training path, with autograd
    net.eval()
    with torch.no_grad():
        state = net.initial_state(B, n, device=device)
        q_steps = []
        for t in range(T):
            q_t, state = net.step(at_step(obs, t), state)
            q_steps.append(q_t)
        # chunked sequences with a carried state (e.g. burn-in) agree too
        q_a, mid = net({k: v[:, :5] for k, v in obs.items()})
        q_b, final_chunks = net({k: v[:, 5:] for k, v in obs.items()}, mid)
    torch.testing.assert_close(torch.stack(q_steps, 1), q_seq.detach(), atol=tol, rtol=tol)
    torch.testing.assert_close(torch.cat([q_a, q_b], 1), q_seq.detach(), atol=tol, rtol=tol)
    for a, b, c in zip(state, final_seq, final_chunks, strict=True):
        torch.testing.assert_close(a, b.detach(), atol=tol, rtol=tol)
        torch.testing.assert_close(c, b.detach(), atol=tol, rtol=tol)


@pytest.mark.parametrize("name", ARCHS)
def test_step_forward_equals_sequence_forward_float64(name: str) -> None:
    B, n, T = 2, 4, 8
    net = small_agent(name, n).double()
    obs = random_obs(B, T, n)
    q_seq, _ = net(obs)
    assert q_seq.dtype == torch.float64
    state = net.initial_state(B, n)
    assert state[0].dtype == torch.float64
    for t in range(T):
        q_t, state = net.step(at_step(obs, t), state)
        torch.testing.assert_close(q_t, q_seq[:, t], atol=1e-12, rtol=1e-12)


def test_step_accepts_observation_batch_from_numpy() -> None:
    n = 5
    rng = np.random.default_rng(0)
    single = [
        dict(
            voltage=rng.normal(-65, 5, n).astype(np.float32),
            target=2,
            pattern=rng.integers(0, 2, N_STEPS).astype(np.int8),
            step=0,
            last_action=-1,
        )
        for _ in range(3)
    ]
    obs = observation_batch(single)
    assert obs["voltage"].shape == (3, n) and obs["target"].dtype == torch.int64
    net = small_agent("tdrqn", n)
    q, _ = net.step(obs, None)
    assert q.shape == (3, n + 1)
    # an already batched dict, as a vector environment returns it
    batched = {k: np.stack([o[k] for o in single]) for k in single[0]}
    for key, value in observation_batch(batched).items():
        assert torch.equal(value, obs[key])
    with pytest.raises(ValueError, match="lacks key"):
        observation_batch([{"voltage": np.zeros(n)}])
    with pytest.raises(ValueError, match="lacks keys"):
        observation_batch({"voltage": np.zeros((2, n))})
    # any integer dtype for the indices, any float dtype for the voltage
    odd = {k: v.int() if k in ("target", "step", "last_action") else v for k, v in obs.items()}
    odd["voltage"] = odd["voltage"].double()
    torch.testing.assert_close(net.step(odd, None)[0], q)


def test_reset_state_zeroes_only_done_rows() -> None:
    net = small_agent("tdrqn", 4)
    _, state = net(random_obs(3, 4, 4))
    done = torch.tensor([False, True, False])
    new = reset_state(state, done)
    for old, s in zip(state, new, strict=True):
        assert torch.equal(s[1], torch.zeros_like(s[1]))
        assert torch.equal(s[0], old[0]) and torch.equal(s[2], old[2])


# ----------------------------------------------------------------------------
# masking


def test_masked_q_and_greedy_action() -> None:
    q = torch.tensor([[0.0, 5.0, 1.0, 2.0], [3.0, 1.0, 9.0, 2.0]])
    mask = torch.tensor([[True, False, True, True], [True, True, False, True]])
    masked = masked_q(q, mask)
    assert masked[0, 1] == float("-inf") and masked[1, 2] == float("-inf")
    assert torch.equal(masked[mask], q[mask])
    # index 0 = do nothing (-1), index j+1 = stimulate neuron j
    assert greedy_action(q).tolist() == [0, 1]
    assert greedy_action(q, mask).tolist() == [2, -1]
    # a [B, n+1] mask over a [B, T, n+1] sequence, broadcast over T
    q_seq = torch.randn(2, 6, 4)
    assert (greedy_action(q_seq, mask[:, None]) + 1 != torch.tensor([1, 2])[:, None]).all()
    assert torch.equal(masked_q(q, mask.to(torch.int8)), masked)  # the envs' int8 masks
    with pytest.raises(TypeError, match="bool"):
        masked_q(q, mask.int())
    with pytest.raises(ValueError, match="n\\+1"):
        masked_q(q, mask[:, :3])


# ----------------------------------------------------------------------------
# permutation equivariance and n-generalisation


@pytest.mark.parametrize("do_nothing_head", ["dueling", "pooled"])
@pytest.mark.parametrize(
    "inputs",
    [dict(inputs=("target",)), dict(inputs=()),
     dict(inputs=("target", "target-voltage", "others-spiking"))],
)  # fmt: skip
@pytest.mark.parametrize("name", EQUIVARIANT)
def test_permutation_equivariance(name: str, inputs: dict, do_nothing_head: str) -> None:
    B, T, n = 3, 9, 6
    net = small_agent(name, n, do_nothing_head=do_nothing_head, **inputs).double()
    assert net.equivariant
    obs = random_obs(B, T, n, seed=1)
    q, _ = net(obs)
    g = torch.Generator().manual_seed(123)
    for _ in range(3):
        perm = torch.randperm(n, generator=g)
        q_p, _ = net(permute_neurons(obs, perm))
        torch.testing.assert_close(q_p[..., 0], q[..., 0], atol=1e-10, rtol=1e-10)
        torch.testing.assert_close(q_p[..., 1:], q[..., 1:][..., perm], atol=1e-10, rtol=1e-10)


@pytest.mark.parametrize("name", FIXED_N)
def test_fixed_n_networks_are_not_equivariant(name: str) -> None:
    B, T, n = 3, 9, 6
    net = small_agent(name, n).double()
    assert not net.equivariant
    obs = random_obs(B, T, n, seed=1)
    q, _ = net(obs)
    perm = torch.tensor([1, 0, 3, 2, 5, 4])
    q_p, _ = net(permute_neurons(obs, perm))
    expected = torch.cat([q[..., :1], q[..., 1:][..., perm]], dim=-1)
    assert (q_p - expected).abs().max() > 1e-4


@pytest.mark.parametrize("name", EQUIVARIANT)
def test_per_neuron_networks_run_on_any_n(name: str) -> None:
    net = small_agent(name, 8)
    for n in (12, 3, 1):
        q, state = net(random_obs(2, 5, n))
        assert q.shape == (2, 5, n + 1)
        assert state[0].shape[:2] == (2, n)
        q1, _ = net.step(at_step(random_obs(2, 1, n), 0), net.initial_state(2, n))
        assert q1.shape == (2, n + 1)


@pytest.mark.parametrize("name", FIXED_N)
def test_fixed_n_networks_refuse_another_n(name: str) -> None:
    net = small_agent(name, 8)
    with pytest.raises(ValueError, match="expected n = 8, got n = 12"):
        net(random_obs(2, 5, 12))
    with pytest.raises(ValueError, match="expected n = 8, got n = 12"):
        net.step(at_step(random_obs(2, 1, 12), 0), None)
    with pytest.raises(ValueError, match="expected n = 8, got n = 12"):
        net.initial_state(2, 12)


# ----------------------------------------------------------------------------
# featurisation and context


def test_shift_pattern_hand_example() -> None:
    pattern = torch.tensor([1, 0, 1, 1, 0], dtype=torch.int8)
    step = torch.tensor([0, 1, 2, 4, 5])
    out = shift_pattern(pattern.expand(5, 5), step, torch.float32)
    expected = torch.tensor(
        [
            [1, 0, 1, 1, 0],  # t = 0: the whole pattern
            [0, 1, 1, 0, -1],  # t = 1: pattern[1:] then one -1
            [1, 1, 0, -1, -1],
            [0, -1, -1, -1, -1],  # t = 4 = N-1: the last element first
            [-1, -1, -1, -1, -1],  # t = N (final observation): all padding
        ],
        dtype=torch.float32,
    )
    assert torch.equal(out, expected)


def test_paper_literal_tdrqn_builds_and_runs() -> None:
    literal = small_agent("tdrqn", 5, inputs=())
    default = small_agent("tdrqn", 5)
    assert literal.lstm.lstm.input_size == 2  # [v_norm, stimulated]
    assert default.lstm.lstm.input_size == 3  # + is-target indicator
    q, _ = literal(random_obs(2, 6, 5))
    assert q.shape == (2, 6, 6) and torch.isfinite(q).all()
    # in the paper-literal variant the target reaches no token before the transformer
    obs = random_obs(2, 6, 5)
    mixed = literal.mixer(literal.lstm(_features(literal, obs), literal.initial_state(2, 5))[0])
    obs["target"] = (obs["target"] + 1) % 5
    mixed2 = literal.mixer(literal.lstm(_features(literal, obs), literal.initial_state(2, 5))[0])
    assert torch.equal(mixed, mixed2)


def test_per_neuron_input_features_on_a_hand_computed_step() -> None:
    from spikectl.agents.inputs import per_neuron_inputs

    # V_r = -70 mV, V_th = -50 mV; neurons 0 and 2 show a spike (V >= V_th, within
    # float32 rounding), 3 is 1 mV short of it; neuron 2 was stimulated, 1 is the target.
    obs = dict(
        voltage=torch.tensor([[-50.0, -60.0, -30.0, -51.0]]),
        last_action=torch.tensor([2]),
        target=torch.tensor([1]),
    )
    x = per_neuron_inputs(obs, ("target", "target-voltage", "others-spiking"),
                          v_rest_mV=-70.0, v_threshold_mV=-50.0, dtype=torch.float32)  # fmt: skip
    expected = [
        # v_norm, stimulated, is target, target's v_norm, others showing a spike
        [1.0, 0.0, 0.0, 0.5, 1.0],
        [0.5, 0.0, 1.0, 0.5, 2.0],
        [2.0, 1.0, 0.0, 0.5, 1.0],
        [0.95, 0.0, 0.0, 0.5, 2.0],
    ]
    torch.testing.assert_close(x, torch.tensor([expected]), atol=1e-6, rtol=0)
    net = small_agent("tdrqn", 4, inputs=("target", "target-voltage", "others-spiking"))
    assert net.lstm.lstm.input_size == 5
    # The features in another order: the same columns, moved.
    moved = per_neuron_inputs(obs, ("others-spiking", "target"), v_rest_mV=-70.0,
                              v_threshold_mV=-50.0, dtype=torch.float32)  # fmt: skip
    torch.testing.assert_close(moved, x[..., [0, 1, 4, 2]], atol=0, rtol=0)


def _features(net: torch.nn.Module, obs: dict[str, torch.Tensor]) -> torch.Tensor:
    from spikectl.agents.inputs import per_neuron_inputs

    return per_neuron_inputs(
        obs, net.sizes.inputs, v_rest_mV=net.v_rest_mV, v_threshold_mV=net.v_threshold_mV,
        dtype=torch.float32,
    )  # fmt: skip


# ----------------------------------------------------------------------------
# sizes, parameter counts, determinism


def test_table2_parameter_counts_same_order_and_smoke_forward(
    capsys: pytest.CaptureFixture,
) -> None:
    sizes = AgentSizes()
    assert (sizes.lstm_hidden, sizes.target_embed + sizes.pattern_embed) == (128, 32)
    assert (sizes.ff_hidden, sizes.head_hidden, sizes.tdrqn_head_hidden) == (
        512,
        (512, 256, 128),
        (256, 128),
    )
    assert (sizes.attn_layers, sizes.attn_heads, sizes.attn_width, sizes.attn_ff) == (
        2,
        1,
        128,
        256,
    )
    counts = parameter_counts(8, 60)
    with capsys.disabled():
        print("\nparameters at Table 2 sizes (n=8, N=60):", counts)
    assert max(counts.values()) / min(counts.values()) < 10
    torch.manual_seed(0)
    obs = random_obs(2, 60, 8, N=60)
    for name in ARCHS:
        net = make_agent(name, 8, 60)
        assert count_parameters(net) == counts[name]
        q, _ = net(obs)
        assert q.shape == (2, 60, 9) and torch.isfinite(q).all()


@pytest.mark.parametrize("name", ARCHS)
def test_same_seed_same_network_and_outputs(name: str) -> None:
    a, b = small_agent(name, 5, seed=7), small_agent(name, 5, seed=7)
    for (ka, va), (kb, vb) in zip(a.state_dict().items(), b.state_dict().items(), strict=True):
        assert ka == kb and torch.equal(va, vb)
    obs = random_obs(2, 6, 5)
    assert torch.equal(a(obs)[0], b(obs)[0])
    c = small_agent(name, 5, seed=8)
    assert not torch.equal(a(obs)[0], c(obs)[0])


# ----------------------------------------------------------------------------
# validation


def test_invalid_observations_give_clear_errors() -> None:
    net = small_agent("tdrqn", 5)
    good = random_obs(2, 4, 5)

    def broken(**changes: object) -> dict[str, object]:
        return {**good, **changes}

    missing = {k: v for k, v in good.items() if k != "pattern"}
    with pytest.raises(ValueError, match="missing keys \\['pattern'\\]"):
        net(missing)
    with pytest.raises(TypeError, match="dict of tensors"):
        net([good])
    with pytest.raises(TypeError, match="must be a torch.Tensor"):
        net(broken(voltage=good["voltage"].numpy()))
    with pytest.raises(TypeError, match="'target'.*integer"):
        net(broken(target=good["target"].float()))
    with pytest.raises(TypeError, match="'voltage'.*floating"):
        net(broken(voltage=good["voltage"].long()))
    with pytest.raises(ValueError, match="'voltage'.*\\[B, T, n\\]"):
        net(broken(voltage=good["voltage"][0]))
    with pytest.raises(ValueError, match="'step'.*shape"):
        net(broken(step=good["step"][:, :3]))
    with pytest.raises(ValueError, match="pattern length = episode length 12"):
        net(broken(pattern=good["pattern"][..., :10]))
    with pytest.raises(ValueError, match="'target'.*\\[0, 4\\]"):
        net(broken(target=good["target"] + 5))
    with pytest.raises(ValueError, match="'last_action'.*\\[-1, 4\\]"):
        net(broken(last_action=good["last_action"] - 2))
    with pytest.raises(ValueError, match="'step'.*\\[0, 12\\]"):
        net(broken(step=good["step"] + 20))
    with pytest.raises(ValueError, match="\\[B, n\\]"):
        net.step(good, None)  # a sequence batch given to step
    with pytest.raises(ValueError, match="state\\[0\\] must have shape"):
        net(good, net.initial_state(3, 5))
    with pytest.raises(TypeError, match="tuple of 2 tensors"):
        net(good, net.initial_state(2, 5)[0])


def test_invalid_construction_gives_clear_errors() -> None:
    with pytest.raises(ValueError, match="unknown agent 'dqn'"):
        make_agent("dqn", 8, 60)
    with pytest.raises(TypeError, match="unknown size fields \\['lstm_size'\\]"):
        make_agent("drqn", 8, 60, lstm_size=64)
    with pytest.raises(ValueError, match="attn_heads"):
        AgentSizes(attn_heads=3)
    with pytest.raises(ValueError, match="do_nothing_head"):
        AgentSizes(do_nothing_head="separate")
    with pytest.raises(ValueError, match="lstm_hidden"):
        AgentSizes(lstm_hidden=0)
    with pytest.raises(ValueError, match="head_hidden"):
        AgentSizes(head_hidden=(64, -1))
    with pytest.raises(ValueError, match="n_neurons"):
        make_agent("tdrqn", 0, 60)
    assert AgentSizes(head_hidden=[32, 16]).head_hidden == (32, 16)  # type: ignore[arg-type]
    assert make_agent("TDRQN", 8, 60, attn_width=64).sizes.attn_width == 64


# ----------------------------------------------------------------------------
# learnability


@pytest.mark.parametrize("name", ARCHS)
def test_fits_fixed_q_targets(name: str) -> None:
    """A few dozen Adam steps on a fixed batch fit Q-targets of the taken actions."""
    B, T, n = 4, N_STEPS, 5
    net = small_agent(name, n)
    obs = random_obs(B, T, n, seed=3)
    g = torch.Generator().manual_seed(4)
    actions = torch.randint(-1, n, (B, T), generator=g)
    # a learnable target: half the normalised potential of the stimulated neuron, 0.25 for
    # "do nothing" (each network sees the current potentials)
    v_norm = (obs["voltage"] + 70.0) / 20.0  # [B, T, n]
    v_taken = v_norm.gather(-1, actions.clamp(min=0).unsqueeze(-1)).squeeze(-1)  # [B, T]
    targets = torch.where(actions >= 0, 0.5 * v_taken, torch.full_like(v_taken, 0.25))
    optimiser = torch.optim.Adam(net.parameters(), lr=5e-3)
    losses = []
    for _ in range(60):
        q, _ = net(obs)
        q_taken = q.gather(-1, (actions + 1).unsqueeze(-1)).squeeze(-1)  # [B, T]
        loss = torch.nn.functional.mse_loss(q_taken, targets)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]


# The state_dict layout the networks had before DDRQN and TDRQN became one class: saved
# model.pt files (SMALL sizes here) must keep loading.
OLD_STATE_DICT_LAYOUT = {
    "ddrqn": [
        ("lstm.lstm.weight_ih_l0", (48, 3)),
        ("lstm.lstm.weight_hh_l0", (48, 12)),
        ("lstm.lstm.bias_ih_l0", (48,)),
        ("lstm.lstm.bias_hh_l0", (48,)),
        ("ff.0.weight", (24, 12)),
        ("ff.0.bias", (24,)),
        ("context.target.0.weight", (4, 1)),
        ("context.target.0.bias", (4,)),
        ("context.pattern.0.weight", (4, 12)),
        ("context.pattern.0.bias", (4,)),
        ("head.advantage.0.weight", (24, 32)),
        ("head.advantage.0.bias", (24,)),
        ("head.advantage.2.weight", (12, 24)),
        ("head.advantage.2.bias", (12,)),
        ("head.advantage.4.weight", (1, 12)),
        ("head.advantage.4.bias", (1,)),
        ("head.value.0.weight", (8, 64)),
        ("head.value.0.bias", (8,)),
        ("head.value.2.weight", (1, 8)),
        ("head.value.2.bias", (1,)),
    ],
    "tdrqn": [
        ("lstm.lstm.weight_ih_l0", (48, 3)),
        ("lstm.lstm.weight_hh_l0", (48, 12)),
        ("lstm.lstm.bias_ih_l0", (48,)),
        ("lstm.lstm.bias_hh_l0", (48,)),
        ("mixer.project.weight", (16, 12)),
        ("mixer.project.bias", (16,)),
        ("mixer.encoder.layers.0.self_attn.in_proj_weight", (48, 16)),
        ("mixer.encoder.layers.0.self_attn.in_proj_bias", (48,)),
        ("mixer.encoder.layers.0.self_attn.out_proj.weight", (16, 16)),
        ("mixer.encoder.layers.0.self_attn.out_proj.bias", (16,)),
        ("mixer.encoder.layers.0.linear1.weight", (32, 16)),
        ("mixer.encoder.layers.0.linear1.bias", (32,)),
        ("mixer.encoder.layers.0.linear2.weight", (16, 32)),
        ("mixer.encoder.layers.0.linear2.bias", (16,)),
        ("mixer.encoder.layers.0.norm1.weight", (16,)),
        ("mixer.encoder.layers.0.norm1.bias", (16,)),
        ("mixer.encoder.layers.0.norm2.weight", (16,)),
        ("mixer.encoder.layers.0.norm2.bias", (16,)),
        ("mixer.encoder.layers.1.self_attn.in_proj_weight", (48, 16)),
        ("mixer.encoder.layers.1.self_attn.in_proj_bias", (48,)),
        ("mixer.encoder.layers.1.self_attn.out_proj.weight", (16, 16)),
        ("mixer.encoder.layers.1.self_attn.out_proj.bias", (16,)),
        ("mixer.encoder.layers.1.linear1.weight", (32, 16)),
        ("mixer.encoder.layers.1.linear1.bias", (32,)),
        ("mixer.encoder.layers.1.linear2.weight", (16, 32)),
        ("mixer.encoder.layers.1.linear2.bias", (16,)),
        ("mixer.encoder.layers.1.norm1.weight", (16,)),
        ("mixer.encoder.layers.1.norm1.bias", (16,)),
        ("mixer.encoder.layers.1.norm2.weight", (16,)),
        ("mixer.encoder.layers.1.norm2.bias", (16,)),
        ("context.target.0.weight", (4, 1)),
        ("context.target.0.bias", (4,)),
        ("context.pattern.0.weight", (4, 12)),
        ("context.pattern.0.bias", (4,)),
        ("head.advantage.0.weight", (16, 24)),
        ("head.advantage.0.bias", (16,)),
        ("head.advantage.2.weight", (8, 16)),
        ("head.advantage.2.bias", (8,)),
        ("head.advantage.4.weight", (1, 8)),
        ("head.advantage.4.bias", (1,)),
        ("head.value.0.weight", (8, 48)),
        ("head.value.0.bias", (8,)),
        ("head.value.2.weight", (1, 8)),
        ("head.value.2.bias", (1,)),
    ],
}


@pytest.mark.parametrize("name", ["ddrqn", "tdrqn"])
def test_state_dict_layout_unchanged_and_loads(name: str) -> None:
    net = make_agent(name, 5, N_STEPS, **SMALL)
    layout = [(key, tuple(value.shape)) for key, value in net.state_dict().items()]
    assert layout == OLD_STATE_DICT_LAYOUT[name]
    old_weights = {key: torch.randn(shape) for key, shape in OLD_STATE_DICT_LAYOUT[name]}
    net.load_state_dict(old_weights, strict=True)
    assert all(net.state_dict()[key].equal(value) for key, value in old_weights.items())
