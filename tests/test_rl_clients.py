"""Real RL clients, as they are, on the flat ids: CleanRL's ppo.py and dqn.py (unmodified
copies in tests/clients, given only the env id and their own size flags), TorchRL's
GymEnv / GymWrapper with check_env_specs, and Stable-Baselines3's check_env and learn().

The tier needs the ``clients`` extra (``pip install -e ".[clients]"``: TorchRL,
Stable-Baselines3) and is skipped without it; .ci/run installs it and runs this file.
RLlib pins an older Gymnasium, so its test runs in a virtual environment of its own
with the ``rllib`` extra (.ci/run makes one).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from packaging.requirements import Requirement

import spikectl  # noqa: F401  (registers the ids)
from spikectl.envs.registration import FLAT_ENV_ID
from spikectl.wrappers import FlatNeuronControlVectorEnv

CLIENTS = Path(__file__).resolve().parent / "clients"
MISSING = [name for name in ("torchrl", "stable_baselines3") if not importlib.util.find_spec(name)]
needs_clients = pytest.mark.skipif(
    bool(MISSING),
    reason=f'the RL client tier needs pip install -e ".[clients]" (missing: {", ".join(MISSING)})',
)


def rllib_unmet() -> list[str]:
    """ray[rllib]'s requirements this environment does not satisfy (all of them without Ray).

    Ray alone (the ``ray`` extra) ships the ``ray.rllib`` package without RLlib's
    dependencies (dm-tree, the Gymnasium it pins, ...), so finding the module is not enough.
    """
    try:
        requirements = importlib.metadata.requires("ray") or []
    except importlib.metadata.PackageNotFoundError:
        return ["ray"]
    unmet = []
    for line in requirements:
        requirement = Requirement(line)
        marker = requirement.marker
        if (
            marker is None
            or not marker.evaluate({"extra": "rllib"})
            or marker.evaluate({"extra": ""})
        ):
            continue  # not one of the rllib extra's
        try:
            installed = importlib.metadata.version(requirement.name)
        except importlib.metadata.PackageNotFoundError:
            unmet.append(requirement.name)
            continue
        if not requirement.specifier.contains(installed, prereleases=True):
            unmet.append(f"{requirement.name}{requirement.specifier} (installed {installed})")
    return unmet


RLLIB_UNMET = rllib_unmet()
needs_rllib = pytest.mark.skipif(
    bool(RLLIB_UNMET),
    reason='RLlib needs its own virtual environment with pip install -e ".[rllib]" '
    f"(unmet: {', '.join(RLLIB_UNMET)})",
)
CLEANRL_ID = f"spikectl:{FLAT_ENV_ID}"  # the module prefix makes gym.make import spikectl


def run_cleanrl(script: str, tmp_path: Path, *size_flags: str) -> str:
    """Run a CleanRL script as a user would, in ``tmp_path`` (it writes runs/ there)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}  # one thread: the machine may be shared
    result = subprocess.run(
        [sys.executable, str(CLIENTS / script), "--env-id", CLEANRL_ID, *size_flags],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    events = list((tmp_path / "runs").rglob("events.out.tfevents.*"))
    assert len(events) == 1, "the script logs to TensorBoard under runs/"
    return result.stdout


def test_cleanrl_scripts_are_the_public_files_unmodified():
    """The copies carry CleanRL's licence and its own header; none of them names spikectl."""
    assert "MIT License" in (CLIENTS / "LICENSE").read_text()
    for script in ("ppo.py", "dqn.py", "cleanrl_utils/buffers.py"):
        text = (CLIENTS / script).read_text()
        assert "spikectl" not in text
    assert "docs.cleanrl.dev" in (CLIENTS / "ppo.py").read_text()


@needs_clients
def test_cleanrl_ppo_runs_on_the_flat_id(tmp_path):
    # 2 iterations of 2 envs x 128 steps: each iteration prints its steps per second.
    stdout = run_cleanrl(
        "ppo.py", tmp_path, "--total-timesteps", "512", "--num-envs", "2", "--num-steps", "128"
    )
    assert stdout.count("SPS:") == 2


@needs_clients
def test_cleanrl_dqn_runs_on_the_flat_id(tmp_path):
    # Random actions (unmasked, illegal ones included) fill the buffer, then it trains.
    stdout = run_cleanrl(
        "dqn.py", tmp_path, "--total-timesteps", "600", "--learning-starts", "300",
        "--batch-size", "32",
    )  # fmt: skip
    assert stdout.count("SPS:") >= 2  # printed every 100 steps once training started


@needs_clients
def test_torchrl_gym_env_passes_check_env_specs():
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    env = GymEnv(FLAT_ENV_ID, contexts={"n_train": 10, "n_test": 10})
    check_env_specs(env, seed=0)
    rollout = env.rollout(130, break_when_any_done=False)  # random one-hot actions
    assert rollout["next", "observation"].shape == (130, 206)
    assert rollout["next", "done"].sum() == 2  # two 60-step episodes ended


@needs_clients
def test_torchrl_wraps_the_batched_simulator():
    """TorchRL resets ended environments itself: the flat batched env with autoreset off."""
    from torchrl.envs import GymWrapper
    from torchrl.envs.utils import check_env_specs

    envs = gym.make_vec(FLAT_ENV_ID, 4, autoreset_mode="Disabled",
                          contexts={"n_train": 10, "n_test": 10})  # fmt: skip
    assert isinstance(envs, FlatNeuronControlVectorEnv)
    env = GymWrapper(envs)
    assert env.batch_size == (4,)
    check_env_specs(env, seed=0)
    rollout = env.rollout(130, break_when_any_done=False)
    assert rollout["next", "reward"].shape == (4, 130, 1)
    assert rollout["next", "done"].sum() == 4 * 2


@needs_clients
def test_sb3_check_env_is_silent_and_ppo_learns_a_few_steps():
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(FLAT_ENV_ID, contexts={"n_train": 10, "n_test": 10}).unwrapped)
    # Given only the id, as SB3 users do (SB3 calls gymnasium.make on it).
    model = PPO("MlpPolicy", FLAT_ENV_ID, n_steps=256, batch_size=64, n_epochs=1, seed=0,
                device="cpu")  # fmt: skip
    model.learn(total_timesteps=512)
    assert model.num_timesteps == 512
    observation = np.zeros(206, dtype=np.float32)
    action, _ = model.predict(observation, deterministic=True)
    assert 0 <= int(action) <= 8


@needs_rllib
def test_rllib_ppo_trains_an_iteration_on_the_batched_simulator():
    """RLlib's PPO given the id; its env runner takes make_vec's batched entry point."""
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    config = (
        PPOConfig()
        .environment(FLAT_ENV_ID, env_config={"contexts": {"n_train": 10, "n_test": 10}})
        .env_runners(
            num_env_runners=0,
            num_envs_per_env_runner=4,
            gym_env_vectorize_mode="vector_entry_point",
        )
        .training(train_batch_size_per_learner=480, minibatch_size=120, num_epochs=1)
    )
    algo = config.build_algo()
    try:
        assert isinstance(algo.env_runner.env.unwrapped, FlatNeuronControlVectorEnv)
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 480
        assert 0.0 <= result["env_runners"]["episode_return_mean"] <= 1.0
    finally:
        algo.stop()
        ray.shutdown()
