"""Where the milliseconds of one TDRQN update and of one collection round go.

Times each part of the trainer's update at a preset's sizes and batch (default: the
quick preset, one Torch thread): the replay sample and input tensors, the online
forward split into its blocks (per-neuron LSTM, transformer across neurons, context
encoder, Q head), their backward passes, the target network's forward, the auxiliary head, gradient
clipping, Adam and the soft update; then one collection round (``num_envs`` episodes
of epsilon-greedy acting) and one greedy evaluation of 100 contexts. Each part is
timed on its own (median of ``--repeats``), interleaved with the whole update, so the
parts can be read as shares of it.

Also compares, in the same run: a bfloat16 autocast of the transformer and a
transformer layer written out with ``scaled_dot_product_attention`` against
``nn.TransformerEncoderLayer`` (the candidates for a cheaper update); with
``--compile``, a whole update whose loss is ``torch.compile``d against the eager one
(the compile time printed apart, the steps interleaved).

    python benchmarks/bench_update_profile.py [--preset quick] [--threads 1] [--repeats 30]
                                              [--compile]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
import torch.nn.functional as F

from spikectl.agents.inputs import per_neuron_inputs
from spikectl.agents.observation import long_indices
from spikectl.contexts import make_splits
from spikectl.envs.rollout import run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.training.greedy_scores import greedy_returns
from spikectl.training.learners.dqn import losses_on_tensors, soft_update, training_losses
from spikectl.training.learners.q_learning import (
    EpsilonGreedyPolicy,
    batch_tensors,
    build_networks,
    build_predictor,
    sequence_observations,
)
from spikectl.training.presets import PRESETS
from spikectl.training.replay import EpisodeReplay


def median_ms(function, repeats: int) -> float:
    for _ in range(3):
        function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times)) * 1e3


def interleaved_medians_ms(candidates: dict, repeats: int) -> dict[str, float]:
    """Median time of each function, the candidates run in turn so that a noisy
    neighbour slows them alike."""
    times = {name: [] for name in candidates}
    for _ in range(repeats):
        for name, function in candidates.items():
            start = time.perf_counter()
            function()
            times[name].append(time.perf_counter() - start)
    return {name: float(np.median(values)) * 1e3 for name, values in times.items()}


def written_out_layer(x: torch.Tensor, layer: torch.nn.TransformerEncoderLayer) -> torch.Tensor:
    """The post-norm, one-head encoder layer with the same weights, written out."""
    width = x.shape[-1]
    qkv = F.linear(x, layer.self_attn.in_proj_weight, layer.self_attn.in_proj_bias)
    query, key, value = qkv.chunk(3, dim=-1)  # [S, n, W] each
    attended = F.scaled_dot_product_attention(query, key, value)  # [S, n, W]
    attended = layer.self_attn.out_proj(attended)
    x = F.layer_norm(x + attended, (width,), layer.norm1.weight, layer.norm1.bias, layer.norm1.eps)
    feed_forward = layer.linear2(F.relu(layer.linear1(x)))
    return F.layer_norm(
        x + feed_forward, (width,), layer.norm2.weight, layer.norm2.bias, layer.norm2.eps
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=sorted(PRESETS), default="quick")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--compile", action="store_true", help="also time a torch.compile'd loss")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = PRESETS[args.preset]
    if config.agent.arch != "tdrqn":
        raise SystemExit("this profile is written for TDRQN")
    rng = np.random.default_rng(0)
    train_set, _ = make_splits(100, 1, config.env.n_neurons, config.env.episode_length)
    online, target = build_networks(config)
    predictor = build_predictor(config, online)
    trained = [*online.parameters(), *(predictor.parameters() if predictor else [])]
    optimizer = torch.optim.Adam(trained, lr=config.learner.learning_rate)
    replay = EpisodeReplay(256, config.env.n_neurons, config.env.episode_length)
    env = NeuronControlVectorEnv(64, contexts=train_set)
    contexts = rng.integers(len(train_set), size=64)
    episodes = run_episodes(env, contexts, EpsilonGreedyPolicy(online, 1.0, rng, "cpu"))
    replay.add(episodes.voltage, episodes.actions, episodes.rewards,
               np.array([train_set[i].target for i in contexts]),
               np.stack([train_set[i].pattern for i in contexts]).astype(np.int8),
               episodes.action_mask)  # fmt: skip

    def update() -> None:
        batch = replay.sample(config.learner.batch_size, rng)
        td, aux = training_losses(
            online, target, batch, config.learner, predictor, config.train.device
        )
        loss = td if aux is None else td + config.learner.aux_voltage_weight * aux
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(trained, config.learner.max_grad_norm)
        optimizer.step()
        soft_update(target, online, config.learner.tau)

    batch = replay.sample(config.learner.batch_size, rng)
    obs = sequence_observations(batch, "cpu")
    indexed = long_indices(obs)
    sizes = online.sizes
    n = config.env.n_neurons
    features = per_neuron_inputs(
        indexed, sizes.inputs, v_rest_mV=online.v_rest_mV, v_threshold_mV=online.v_threshold_mV,
        dtype=torch.float32,
    )  # fmt: skip
    state = online.initial_state(config.learner.batch_size, n)
    lstm_out = online.lstm(features, state)[0].detach().requires_grad_()
    mixed = online.mixer(lstm_out).detach()
    head_in = torch.cat([mixed, online.context(indexed, n)], -1).detach().requires_grad_()

    def forward_backward(function):
        def run() -> None:
            out = function()
            (out[0] if isinstance(out, tuple) else out).sum().backward()

        return run

    parts = {
        "replay sample + input tensors": lambda: sequence_observations(
            replay.sample(config.learner.batch_size, rng), "cpu"
        ),
        "per-neuron LSTM, forward + backward": forward_backward(
            lambda: online.lstm(features, state)
        ),
        "transformer across neurons, forward + backward": forward_backward(
            lambda: online.mixer(lstm_out)
        ),
        "context encoder, forward + backward": forward_backward(lambda: online.context(indexed, n)),
        "Q head, forward + backward": forward_backward(
            lambda: online.head(head_in, indexed["target"])
        ),
        "target network forward (no grad)": torch.no_grad()(lambda: target(obs)),
    }
    if predictor is not None:
        actions = torch.as_tensor(batch.actions)
        parts["auxiliary voltage head, forward + backward"] = forward_backward(
            lambda: predictor(mixed.detach().requires_grad_()[:, :-1], actions)
        )
    results = {"whole update": median_ms(update, args.repeats)}
    for name, function in parts.items():
        results[name] = median_ms(function, args.repeats)
    update()
    results["gradient clip"] = median_ms(
        lambda: torch.nn.utils.clip_grad_norm_(trained, config.learner.max_grad_norm),
        args.repeats,
    )
    results["Adam step"] = median_ms(optimizer.step, args.repeats)
    results["soft target update"] = median_ms(
        lambda: soft_update(target, online, config.learner.tau), args.repeats
    )
    collect_env = NeuronControlVectorEnv(config.train.num_envs, contexts=train_set)
    results[f"collection round ({config.train.num_envs} episodes, epsilon 0.5)"] = median_ms(
        lambda: run_episodes(
            collect_env, rng.integers(len(train_set), size=config.train.num_envs),
            EpsilonGreedyPolicy(online, 0.5, rng, "cpu"),
        ),
        max(args.repeats // 5, 3),
    )  # fmt: skip
    eval_env = NeuronControlVectorEnv(len(train_set), contexts=train_set)
    results["greedy evaluation of 100 contexts"] = median_ms(
        lambda: greedy_returns(online, eval_env, "cpu", seed=0), max(args.repeats // 5, 3)
    )

    whole = results["whole update"]
    length = config.env.episode_length
    shape = f"{config.learner.batch_size} episodes x {length + 1} steps x {n} neurons"
    print(f"torch {torch.__version__}, {torch.get_num_threads()} thread(s), {args.preset} "
          f"preset, batch {shape}")  # fmt: skip
    print("| part | median (ms) | share of one update |")
    print("|---|---:|---:|")
    for name, value in results.items():
        per_update = "collection" not in name and "evaluation" not in name
        share = f"{value / whole:.0%}" if per_update else ""
        print(f"| {name} | {value:.2f} | {share} |")

    print("\nCandidates for a cheaper transformer (forward + backward, same run):")
    mixer = online.mixer
    batch_size, steps = lstm_out.shape[:2]

    def written_out() -> torch.Tensor:
        x = mixer.project(lstm_out).reshape(batch_size * steps, n, -1)  # [B*T, n, W]
        for layer in mixer.encoder.layers:
            x = written_out_layer(x, layer)
        return x

    with torch.no_grad():
        difference = (written_out().reshape_as(mixed) - mixer(lstm_out)).abs().max().item()

    def autocast_bf16() -> torch.Tensor:
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return mixer(lstm_out).float()

    candidates = {
        "nn.TransformerEncoderLayer (today)": forward_backward(lambda: mixer(lstm_out)),
        f"written out, SDPA (max |diff| {difference:.1e})": forward_backward(written_out),
        "bfloat16 autocast": forward_backward(autocast_bf16),
    }
    medians = interleaved_medians_ms(candidates, args.repeats)
    reference = medians["nn.TransformerEncoderLayer (today)"]
    print("| transformer | median (ms) | ratio to today |")
    print("|---|---:|---:|")
    for name, value in medians.items():
        print(f"| {name} | {value:.2f} | {value / reference:.2f} |")
    if args.compile:
        compare_compiled_update(online, target, predictor, trained, optimizer, replay, rng,
                                config, args.repeats)  # fmt: skip


def compare_compiled_update(
    online, target, predictor, trained, optimizer, replay, rng, config, repeats
) -> None:
    """A whole update with the loss compiled by ``torch.compile`` against the eager one."""

    def loss_of(tensors: dict) -> torch.Tensor:
        td, aux = losses_on_tensors(online, target, tensors, config.learner, predictor)
        return td if aux is None else td + config.learner.aux_voltage_weight * aux

    def update_with(loss_function):
        def run() -> None:
            batch = replay.sample(config.learner.batch_size, rng)
            loss = loss_function(batch_tensors(batch, "cpu"))
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(trained, config.learner.max_grad_norm)
            optimizer.step()
            soft_update(target, online, config.learner.tau)

        return run

    compiled = update_with(torch.compile(loss_of, dynamic=False))
    start = time.perf_counter()
    for _ in range(3):  # the first calls compile (and recompile for the no-grad pass)
        compiled()
    print(f"\ntorch.compile: first 3 updates took {time.perf_counter() - start:.1f} s")
    medians = interleaved_medians_ms(
        {"eager update": update_with(loss_of), "compiled loss": compiled}, repeats
    )
    print("| update | median (ms) | ratio to eager |")
    print("|---|---:|---:|")
    for name, value in medians.items():
        print(f"| {name} | {value:.2f} | {value / medians['eager update']:.2f} |")


if __name__ == "__main__":
    main()
