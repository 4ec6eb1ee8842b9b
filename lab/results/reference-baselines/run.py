"""One reference baseline: a generic RL algorithm, as its library publishes it, trained on
a suite task's flat id and scored on the task's test networks as the suite scores.

    python lab/results/reference-baselines/run.py ALGORITHM TASK SEED [--steps 1000000]

ALGORITHM is one of :data:`ALGORITHMS`; TASK one of :data:`TASK_IDS`. CleanRL's scripts
(``ppo.py`` and ``dqn.py`` in tests/third_party/cleanrl; ``pqn.py`` downloaded from
:data:`PQN_URL` into the folder ``--cleanrl-dir`` names) run unmodified through ``runpy``
with only the id, the step budget and the seed on their command line, and the trained
network is read from the script's globals afterwards (the scripts save nothing by default). SB3 and
sb3-contrib run with their defaults on the batched simulator (``sb3_vec_env``).

The trained policy is then played greedily (argmax; ``deterministic=True``) on the
task's 100 test networks through ``suite.score`` (``FlatPolicyController``), and the run
writes ``docs/results/reference-baselines/TASK/ALGORITHM/seedS/``: ``result.json`` (test
mean return, normalised score, standard error, CPU, core-minutes, the command),
``test-per-network.csv`` and ``curve.csv`` (training episodes' mean return per 20 000
steps). Training uses one thread (``OMP_NUM_THREADS=1``), so its CPU seconds are
core-seconds.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before torch: one core a run

import argparse
import contextlib
import csv
import io
import json
import platform
import resource
import runpy
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repository root: lab
from lab.records import write_csv
from spikectl.experiments import suite
from spikectl.wrappers import FlatPolicyController, final_info_id, sb3_vec_env

ROOT = Path(__file__).resolve().parents[3]
OUT = ROOT / "docs" / "results" / "reference-baselines"
CLIENTS = ROOT / "tests" / "third_party" / "cleanrl"

TASK_IDS = {
    "paper": "spikectl/NeuronControl-v0",
    "n16": "spikectl/NeuronControl16-v0",
    "noise2": "spikectl/NeuronControlNoisy-v0",
}
"""Each task's id: its train networks are the suite task's train set (same checksum).
CleanRL plays its flat twin (``...Flat...``), through the ``FinalInfo`` twin so that the
scripts log episodic returns; SB3 the batched paper id behind ``sb3_vec_env``."""


def flat_twin(env_id: str) -> str:
    return env_id.replace("-v0", "Flat-v0")


SB3_ENVS = 16
"""Environments of the batched simulator for SB3's algorithms (examples/sb3_maskable_ppo.py)."""

CURVE_BIN_STEPS = 20_000


def cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor()


PQN_COMMIT = "fe8d8a03c41a7ef5b523e2e354bd01c363e786bb"
PQN_URL = f"https://raw.githubusercontent.com/vwxyzjn/cleanrl/{PQN_COMMIT}/cleanrl/pqn.py"
"""CleanRL's ``pqn.py`` (its classic-control PQN, on Gymnasium ids) as published at that
commit. It is not kept in the tree: ``--cleanrl-dir`` names the folder it was downloaded to."""


def _cleanrl(script: Path, env_id: str, steps: int, seed: int, work: Path):
    """Run CleanRL's ``script`` unmodified; (its globals, episode (step, return) pairs)."""
    argv = [str(script), "--env-id", final_info_id(flat_twin(env_id)),
            "--total-timesteps", str(steps), "--seed", str(seed)]  # fmt: skip
    saved_argv, saved_cwd = sys.argv, os.getcwd()
    sys.argv = argv
    sys.path.insert(0, str(CLIENTS))  # as running the script from its folder would: cleanrl_utils
    os.chdir(work)  # the script's TensorBoard runs/ folder goes here
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # one line per episode
            scope = runpy.run_path(argv[0], run_name="__main__")
    finally:
        sys.argv = saved_argv
        sys.path.remove(str(CLIENTS))
        os.chdir(saved_cwd)
    return scope, _tensorboard_episodes(work / "runs")


def _tensorboard_episodes(runs: Path) -> list[tuple[int, float]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    # The run's name holds the id, whose "/" makes a sub-folder: find the one events file.
    (path,) = runs.rglob("events.out.tfevents.*")
    events = EventAccumulator(str(path), size_guidance={"scalars": 0})
    events.Reload()
    return [(int(e.step), float(e.value)) for e in events.Scalars("charts/episodic_return")]


def _greedy_torch(network) -> callable:
    def policy(observations: np.ndarray, action_mask: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return network(torch.as_tensor(observations)).argmax(dim=1).numpy()

    return policy


def train_cleanrl_ppo(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    scope, episodes = _cleanrl(CLIENTS / "ppo.py", env_id, steps, seed, work)
    return _greedy_torch(scope["agent"].actor), None, episodes


def train_cleanrl_dqn(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    scope, episodes = _cleanrl(CLIENTS / "dqn.py", env_id, steps, seed, work)
    return _greedy_torch(scope["q_network"]), None, episodes


def train_cleanrl_pqn(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    scope, episodes = _cleanrl(cleanrl_dir / "pqn.py", env_id, steps, seed, work)
    return _greedy_torch(scope["q_network"]), None, episodes


def _sb3(algorithm_class, policy_name: str, env_id, steps, seed, work, **kwargs):
    from stable_baselines3.common.vec_env import VecMonitor

    venv = VecMonitor(sb3_vec_env(gym.make_vec(env_id, num_envs=SB3_ENVS)), str(work / "monitor"))
    model = algorithm_class(policy_name, venv, seed=seed, device="cpu", **kwargs)
    model.learn(steps)
    venv.close()
    with open(work / "monitor.monitor.csv") as handle:
        next(handle)  # the monitor's JSON header line
        rows = list(csv.DictReader(handle))
    lengths = np.cumsum([int(row["l"]) for row in rows])
    # VecMonitor writes episodes as they end; the step is the total of steps so far.
    episodes = [(int(step), float(row["r"])) for step, row in zip(lengths, rows, strict=True)]
    return model, episodes


def _sb3_greedy(model):
    return lambda observations, mask: model.predict(observations, deterministic=True)[0]


def train_sb3_maskable_ppo(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    from sb3_contrib import MaskablePPO

    model, episodes = _sb3(MaskablePPO, "MlpPolicy", env_id, steps, seed, work)

    def policy(observations, action_mask):
        actions, _ = model.predict(observations, action_masks=action_mask.astype(bool),
                                   deterministic=True)  # fmt: skip
        return actions

    return policy, None, episodes


def train_sb3_ppo(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    from stable_baselines3 import PPO

    model, episodes = _sb3(PPO, "MlpPolicy", env_id, steps, seed, work)
    return _sb3_greedy(model), None, episodes


def train_sb3_recurrent_ppo(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    from sb3_contrib import RecurrentPPO

    model, episodes = _sb3(RecurrentPPO, "MlpLstmPolicy", env_id, steps, seed, work)
    memory: dict = {}

    def reset() -> None:
        memory.clear()

    def policy(observations, action_mask):
        starts = np.full(len(observations), "state" not in memory)
        actions, memory["state"] = model.predict(
            observations, state=memory.get("state"), episode_start=starts, deterministic=True
        )
        return actions

    return policy, reset, episodes


def train_sb3_dqn(env_id, steps, seed, work, cleanrl_dir=CLIENTS):
    from stable_baselines3 import DQN

    model, episodes = _sb3(DQN, "MlpPolicy", env_id, steps, seed, work)
    return _sb3_greedy(model), None, episodes


ALGORITHMS = {
    "cleanrl-ppo": train_cleanrl_ppo,
    "cleanrl-dqn": train_cleanrl_dqn,
    "cleanrl-pqn": train_cleanrl_pqn,
    "sb3-ppo": train_sb3_ppo,
    "sb3-maskable-ppo": train_sb3_maskable_ppo,
    "sb3-recurrent-ppo": train_sb3_recurrent_ppo,
    "sb3-dqn": train_sb3_dqn,
}


def curve(episodes: list[tuple[int, float]], steps: int) -> list[dict]:
    rows = []
    for end in range(CURVE_BIN_STEPS, steps + 1, CURVE_BIN_STEPS):
        returns = [r for step, r in episodes if end - CURVE_BIN_STEPS < step <= end]
        rows.append({"step": end, "episodes": len(returns),
                     "mean_return": f"{np.mean(returns):.6f}" if returns else ""})  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("algorithm", choices=list(ALGORITHMS))
    parser.add_argument("task", choices=list(TASK_IDS))
    parser.add_argument("seed", type=int)
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--cleanrl-dir", type=Path, default=CLIENTS,
                        help=f"the folder holding CleanRL's pqn.py ({PQN_URL})")  # fmt: skip
    args = parser.parse_args()
    if args.algorithm == "cleanrl-pqn" and not (args.cleanrl_dir / "pqn.py").is_file():
        parser.error(f"no pqn.py in {args.cleanrl_dir}: download {PQN_URL} there "
                     "and name the folder with --cleanrl-dir")  # fmt: skip
    torch.set_num_threads(1)
    run_dir = args.out / args.task / args.algorithm / f"seed{args.seed}"
    if (run_dir / "result.json").exists():
        print(f"{run_dir}: done already")
        return
    run_dir.mkdir(parents=True, exist_ok=True)

    started = time.time()
    with tempfile.TemporaryDirectory() as work:
        policy, reset, episodes = ALGORITHMS[args.algorithm](
            TASK_IDS[args.task], args.steps, args.seed, Path(work), args.cleanrl_dir
        )
    usage = resource.getrusage(resource.RUSAGE_SELF)
    train_cpu = usage.ru_utime + usage.ru_stime
    env = gym.make(TASK_IDS[args.task])
    controller = FlatPolicyController.for_env(policy, env, reset)
    score = suite.score(args.task, "test", lambda seed: controller)
    nothing, oracle = suite.references(args.task, "test")
    contexts = suite.load_split(args.task, "test")

    write_csv(run_dir / "curve.csv", curve(episodes, args.steps))
    write_csv(run_dir / "test-per-network.csv", [
        {"network": index, "return": f"{value:.6f}"} for index, value in enumerate(score.returns)
    ])  # fmt: skip
    result = {
        "algorithm": args.algorithm,
        "task": args.task,
        "env_id": TASK_IDS[args.task],
        "seed": args.seed,
        "steps": args.steps,
        "test_networks": len(contexts),
        "test_mean_return": round(score.mean_return, 6),
        "test_standard_error": round(score.standard_error, 6),
        "test_normalised": round(suite.normalise(score.mean_return, nothing, oracle), 6),
        "train_core_minutes": round(train_cpu / 60, 2),
        "wall_minutes": round((time.time() - started) / 60, 2),
        "eval_cpu_seconds": round(score.cpu_seconds, 2),
        "cpu": cpu_model(),
        "torch": torch.__version__,
        "commit": subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip(),  # fmt: skip
        "command": "python lab/results/reference-baselines/run.py "
        f"{args.algorithm} {args.task} {args.seed} --steps {args.steps}"
        + (" --cleanrl-dir DIR" if args.algorithm == "cleanrl-pqn" else ""),
    }
    temporary = run_dir / "result.tmp"
    temporary.write_text(json.dumps(result, indent=1) + "\n")
    temporary.replace(run_dir / "result.json")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
