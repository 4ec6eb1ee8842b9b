"""Training speed of the RL clients of docs/ecosystem.md on the flat ids, a few thousand
environment steps each (docs/ecosystem.md, "Which to pick").

Each client trains as the docs show it, with its own defaults except the sizes below,
on one PyTorch thread; the number is environment steps per second of training (the
updates and the setup of its model included), wall clock, after a short warm-up run that
compiles the simulator. CleanRL's scripts print their own SPS (from after their
environments are made); the last one printed is taken. RLlib's first iteration, which
starts Ray and the remote env runner, is not timed.

    OMP_NUM_THREADS=1 python benchmarks/bench_clients.py CLIENT [--steps 8192]

CLIENT: cleanrl-ppo, cleanrl-dqn (tests/third_party/cleanrl, as published), sb3-ppo, maskable-ppo
(the ``sb3`` extra), skrl-dqn (skrl), rllib-ppo (the ``rllib`` extra, in its own
virtual environment). Each needs its client installed.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym

import spikectl  # noqa: F401  (registers the environment ids)
from spikectl.envs.registration import FLAT_ENV_ID
from spikectl.wrappers import final_info_id

CLIENTS = Path(__file__).resolve().parent.parent / "tests" / "third_party" / "cleanrl"


def cleanrl(script: str, steps: int, *flags: str) -> float:
    env_id = f"spikectl:{final_info_id(FLAT_ENV_ID)}"
    with tempfile.TemporaryDirectory() as out:
        command = [sys.executable, str(CLIENTS / script), "--env-id", env_id,
                   "--total-timesteps", str(steps), *flags]  # fmt: skip
        stdout = subprocess.run(command, cwd=out, check=True, capture_output=True, text=True)
    return float(re.findall(r"SPS: (\d+)", stdout.stdout)[-1])


def timed(train, steps: int) -> tuple[float, int]:
    """Steps per second and steps done: a client may run past ``steps`` to the end of
    its rollout (MaskablePPO's first is 16 x 2048 steps)."""
    start = time.perf_counter()
    done = train(steps)
    return done / (time.perf_counter() - start), done


def sb3_ppo(steps: int) -> int:
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", FLAT_ENV_ID, device="cpu", seed=0)  # one env, n_steps 2048
    return model.learn(steps).num_timesteps


def maskable_ppo(steps: int) -> int:
    from sb3_contrib import MaskablePPO

    from spikectl.wrappers import sb3_vec_env

    venv = sb3_vec_env(gym.make_vec("spikectl/NeuronControl-v0", num_envs=16))
    return MaskablePPO("MlpPolicy", venv, device="cpu", seed=0).learn(steps).num_timesteps


def skrl_dqn(steps: int) -> int:
    from skrl.agents.torch.dqn import DQN
    from skrl.envs.wrappers.torch import wrap_env
    from skrl.memories.torch import RandomMemory
    from skrl.trainers.torch import SequentialTrainer
    from skrl.utils.model_instantiators.torch import deterministic_model

    env = wrap_env(gym.make_vec(FLAT_ENV_ID, 8), verbose=False)
    network = [{"name": "net", "input": "OBSERVATIONS", "layers": [64, 64], "activations": "relu"}]
    models = {
        role: deterministic_model(observation_space=env.observation_space,
                                  action_space=env.action_space, device="cpu",
                                  network=network, output="ACTIONS")
        for role in ("q_network", "target_q_network")
    }  # fmt: skip
    memory = RandomMemory(memory_size=10_000, num_envs=8, device="cpu")
    with tempfile.TemporaryDirectory() as out:
        agent = DQN(models=models, memory=memory, observation_space=env.observation_space,
                    action_space=env.action_space, device="cpu",
                    cfg={"learning_starts": 100, "experiment": {"directory": out}})  # fmt: skip
        cfg = {"timesteps": steps // 8, "headless": True, "disable_progressbar": True,
               "close_environment_at_exit": False}  # fmt: skip
        SequentialTrainer(env=env, agents=agent, cfg=cfg).train()
    env.close()
    return steps // 8 * 8


def rllib_ppo(steps: int) -> tuple[float, int]:
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    config = (
        PPOConfig()
        .environment(f"spikectl:{FLAT_ENV_ID}")
        .env_runners(num_env_runners=1, num_envs_per_env_runner=16,
                     gym_env_vectorize_mode="vector_entry_point")
    )  # fmt: skip
    algo = config.build_algo()
    try:
        # The first iteration starts Ray's workers and the remote env runner: not timed.
        first = int(algo.train()["env_runners"]["num_env_steps_sampled_lifetime"])
        start, done = time.perf_counter(), 0
        while done < steps:
            lifetime = algo.train()["env_runners"]["num_env_steps_sampled_lifetime"]
            done = int(lifetime) - first
        return done / (time.perf_counter() - start), done
    finally:
        algo.stop()
        ray.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("client", choices=["cleanrl-ppo", "cleanrl-dqn", "sb3-ppo",
                                           "maskable-ppo", "skrl-dqn", "rllib-ppo"])  # fmt: skip
    parser.add_argument("--steps", type=int, default=8192)
    args = parser.parse_args()
    gym.make_vec(FLAT_ENV_ID, 2).reset(seed=0)  # compile (or load) the simulator first
    done = args.steps
    if args.client == "cleanrl-ppo":
        sps = cleanrl("ppo.py", args.steps)  # 4 envs x 128 steps per iteration
    elif args.client == "cleanrl-dqn":
        sps = cleanrl("dqn.py", args.steps, "--learning-starts", str(args.steps // 4))
    elif args.client == "rllib-ppo":
        sps, done = rllib_ppo(args.steps)
    else:
        train = {"sb3-ppo": sb3_ppo, "maskable-ppo": maskable_ppo,
                 "skrl-dqn": skrl_dqn}[args.client]  # fmt: skip
        sps, done = timed(train, args.steps)
    print(f"{args.client}: {sps:.0f} environment steps per second ({done} steps)")


if __name__ == "__main__":
    main()
