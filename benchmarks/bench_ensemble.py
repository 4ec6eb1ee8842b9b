"""Seed groups against separate processes: training throughput of K seeds.

The same work two ways, each timed from the outside (process start to exit, imports and
the first and last evaluation included, as a user pays them):

- batched: ``spikectl train --seeds 0 .. K-1 --stacked`` (one process, stacked networks), with
  1 and with 2 Torch threads;
- separate: K single-seed ``spikectl train`` processes, at most ``--cores`` at a time,
  one Torch thread each (how ``spikectl sweep`` runs trials).

Every run is the ``quick`` preset (TDRQN, half-width networks, batches of 8 episodes)
cut to ``--rounds`` collection rounds of 16 episodes and ``--updates-per-round``
updates each. Reported: env steps/s and updates/s summed over the K seeds, and the
batched/separate throughput ratio, median over ``--repeats`` interleaved repeats.

``--micro`` instead times the two parts in this process: one gradient update (sample,
losses, backward, clip, Adam) and one acting step (16 episodes) of K stacked seeds
against K times one plain network's, one thread, at the sizes of ``--preset`` (quick
by default; paper is Table 2) on ``--device`` (cpu by default; cuda times the GPU path,
synchronising before each clock read, eager and replayed as CUDA graphs).

    python benchmarks/bench_ensemble.py               # K = 2, 5, 10, 3 rounds
    python benchmarks/bench_ensemble.py --quick       # K = 2, 1 round of 4 updates
    python benchmarks/bench_ensemble.py --micro --seeds 1 2 5 10
    python benchmarks/bench_ensemble.py --micro --preset paper --device cuda --seeds 1 10 40
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from spikectl.training.presets import PRESETS, QUICK


def train_flags(rounds: int, updates_per_round: int) -> list[str]:
    steps = rounds * QUICK.train.num_envs * QUICK.env.episode_length
    never = str(10**9)
    return ["train", "quick", "--total-env-steps", str(steps),
            "--updates-per-round", str(updates_per_round), "--eval-every-episodes", never,
            "--checkpoint-every-episodes", never, "--no-progress"]  # fmt: skip


def run_processes(commands: list[list[str]], cores: int) -> float:
    """Wall seconds to run every command, at most ``cores`` at once."""
    started = time.perf_counter()
    pending, running = list(commands), []
    while pending or running:
        while pending and len(running) < cores:
            running.append(subprocess.Popen([sys.executable, "-m", "spikectl.cli", *pending.pop(0)],
                                            stdout=subprocess.DEVNULL))  # fmt: skip
        for process in list(running):
            if process.poll() is not None:
                if process.returncode:
                    raise RuntimeError(f"a benchmark run failed (exit {process.returncode})")
                running.remove(process)
        time.sleep(0.05)
    return time.perf_counter() - started


def micro(seeds: list[int], repeats: int, preset: str, device: str) -> None:
    """Milliseconds per update and per acting step: K stacked seeds against K plain."""
    import numpy as np
    import torch

    from spikectl.training.learners.dqn import training_losses
    from spikectl.training.learners.q_learning import build_networks, build_predictor
    from spikectl.training.replay import EpisodeReplay

    torch.set_num_threads(1)
    config = PRESETS[preset].with_changes(device=device)
    rng = np.random.default_rng(0)
    n, N, E = config.env.n_neurons, config.env.episode_length, 64
    replay = EpisodeReplay(E, n, N)
    replay.add((rng.random((E, N + 1, n)) * 25 - 70).astype(np.float32),
               rng.integers(-1, n, (E, N)), rng.random((E, N)).astype(np.float32),
               rng.integers(0, n, E), rng.integers(0, 2, (E, N)).astype(np.int8),
               np.ones((E, n + 1), dtype=bool))  # fmt: skip

    def sync() -> None:
        if config.train.device.startswith("cuda"):
            torch.cuda.synchronize()

    def timed(step, count: int) -> float:
        step()
        times = []
        for _ in range(count):
            sync()
            started = time.perf_counter()
            step()
            sync()
            times.append(time.perf_counter() - started)
        return statistics.median(times) * 1e3

    online, target = build_networks(config)
    predictor = build_predictor(config, online)
    params = list(online.parameters()) + (list(predictor.parameters()) if predictor else [])
    adam = torch.optim.Adam(params, lr=config.learner.learning_rate)

    def single_update() -> None:
        batch = replay.sample(config.learner.batch_size, rng)
        td, aux = training_losses(
            online, target, batch, config.learner, predictor, config.train.device
        )
        adam.zero_grad()
        (td if aux is None else td + config.learner.aux_voltage_weight * aux).backward()
        torch.nn.utils.clip_grad_norm_(params, config.learner.max_grad_norm)
        adam.step()

    def observation(lead: tuple[int, ...]) -> dict[str, torch.Tensor]:
        tensors = {"voltage": torch.rand(*lead, n) * 25 - 70, "target": torch.zeros(lead).long(),
                   "pattern": torch.ones(*lead, N), "step": torch.zeros(lead).long(),
                   "last_action": torch.full(lead, -1)}  # fmt: skip
        return {key: value.to(config.train.device) for key, value in tensors.items()}

    single_obs = observation((16,))
    with torch.no_grad():
        single_step = timed(lambda: online.step(single_obs, None), 10 * repeats)
    single = timed(single_update, 5 * repeats)
    print(f"{preset} sizes on {device}, batch {config.learner.batch_size} episodes of {N} steps, "
          f"{n} neurons, {config.agent.arch}")  # fmt: skip
    print(f"one plain network: update {single:.0f} ms, acting step {single_step:.1f} ms")
    graphs = [False, True] if config.train.device.startswith("cuda") else [False]
    print(f"{'K':>3} {'how':<7}{'update ms':>11}{'per seed':>10}{'vs K plain':>12}"
          f"{'step ms':>9}{'vs K plain':>12}")  # fmt: skip
    for K in seeds:
        for cuda_graphs in graphs:
            update, step = stacked_timings(config, K, replay, rng, observation, timed, repeats,
                                           cuda_graphs)  # fmt: skip
            how = "graph" if cuda_graphs else "eager"
            print(
                f"{K:>3} {how:<7}{update:>11.1f}{update / K:>10.1f}"
                f"{K * single / update:>11.2f}x{step:>9.2f}{K * single_step / step:>11.2f}x"
            )


def stacked_timings(
    config, K: int, replay, rng, observation, timed, repeats: int, cuda_graphs: bool = False
) -> tuple[float, float]:
    """Milliseconds of one update and one acting step of K stacked seeds of ``config``
    (the learner's own ``StackedDQN.update`` and ``acting_step``; with ``cuda_graphs``
    both replayed as CUDA graphs, captured before the clock starts)."""

    import numpy as np

    from spikectl.training.learners.dqn_stacked import StackedDQN
    from spikectl.training.run_sets import generated_contexts

    config = config.with_changes(updates_per_round=1, learning_starts=1, cuda_graphs=cuda_graphs)
    train_set = generated_contexts(config)[0]
    group = StackedDQN([config.with_changes(seed=s) for s in range(K)], [train_set] * K,
                       [np.random.default_rng(s) for s in range(K)])  # fmt: skip
    for seed in group.seeds:
        seed.replay = replay

    obs = observation((K, 16))
    device = config.train.device
    state = group.online.template.initial_state(16, config.env.n_neurons, device=device)
    state = tuple(s.expand(K, *s.shape).clone() for s in state)
    step = timed(lambda: group.acting_step(obs, state), 10 * repeats)
    return timed(lambda: group.update(0), 3 * repeats), step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[2, 5, 10], help="values of K")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--updates-per-round", type=int, default=QUICK.learner.updates_per_round)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--cores", type=int, default=2, help="separate processes at once")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--quick", action="store_true", help="K = 2, 1 round of 4 updates")
    parser.add_argument("--micro", action="store_true", help="time update and step in-process")
    parser.add_argument("--preset", choices=sorted(PRESETS), default="quick", help="--micro sizes")
    parser.add_argument("--device", default="cpu", help="--micro device: cpu, cuda, ...")
    args = parser.parse_args()
    if args.micro:
        micro(args.seeds, args.repeats, args.preset, args.device)
        return
    if args.quick:
        args.seeds, args.rounds, args.updates_per_round = [2], 1, 4
    flags = train_flags(args.rounds, args.updates_per_round)
    steps = args.rounds * QUICK.train.num_envs * QUICK.env.episode_length
    updates = args.rounds * args.updates_per_round
    print(f"quick preset, {args.rounds} round(s) x {QUICK.train.num_envs} episodes, "
          f"{updates} updates per seed; separate runs {args.cores} at a time")  # fmt: skip
    print(f"{'K':>3} {'how':<22}{'wall s':>9}{'env steps/s':>13}{'updates/s':>11}{'ratio':>7}")
    for K in args.seeds:
        walls: dict[str, list[float]] = {}
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as scratch:
                root = Path(scratch)
                separate = [[*flags, "--seed", str(s), "--torch-threads", "1",
                             "--run-dir", str(root / f"single{s}")] for s in range(K)]  # fmt: skip
                walls.setdefault("separate, 1 thread", []).append(
                    run_processes(separate, args.cores)
                )
                for threads in args.threads:
                    group = [*flags, "--seeds", *map(str, range(K)), "--stacked", "--torch-threads",
                             str(threads), "--run-dir", str(root / f"group{threads}")]  # fmt: skip
                    walls.setdefault(f"batched, {threads} thread(s)", []).append(
                        run_processes([group], 1)
                    )
        baseline = statistics.median(walls["separate, 1 thread"])
        for how, times in walls.items():
            wall = statistics.median(times)
            print(f"{K:>3} {how:<22}{wall:>9.1f}{K * steps / wall:>13.0f}"
                  f"{K * updates / wall:>11.2f}{baseline / wall:>7.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
