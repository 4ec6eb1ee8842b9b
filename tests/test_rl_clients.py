"""Real RL clients, as they are, on the flat ids: CleanRL's ppo.py and dqn.py (unmodified
copies in tests/third_party/cleanrl, given only the env id and their own size flags), TorchRL's
GymEnv / GymWrapper with check_env_specs, Stable-Baselines3's check_env and learn(),
skrl's wrap_env and DQN, and RLlib's PPO with a remote env runner.

The tier needs the ``clients`` extra (``pip install -e ".[clients]"``: TorchRL,
Stable-Baselines3) and is skipped without it; .ci/run installs it and runs this file.
The skrl tests skip only where skrl is not installed. RLlib pins an older Gymnasium, so
its test runs in a virtual environment of its own with the ``rllib`` extra (.ci/run
makes one).
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
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.wrappers import FlatNeuronControlVectorEnv, final_info_id

CLIENTS = Path(__file__).resolve().parent / "third_party" / "cleanrl"
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
needs_skrl = pytest.mark.skipif(
    not importlib.util.find_spec("skrl"), reason="skrl is not installed (pip install skrl)"
)
# The module prefix makes gym.make import spikectl first, in whichever process makes the
# environment: a CleanRL script, an RLlib env runner, a TorchRL worker.
IMPORTING_FLAT_ID = f"spikectl:{FLAT_ENV_ID}"
SMALL = {"contexts": {"n_train": 10, "n_test": 10}}  # ten networks a split: quick to generate


def run_cleanrl(
    script: str, tmp_path: Path, *size_flags: str, env_id: str = IMPORTING_FLAT_ID
) -> str:
    """Run a CleanRL script as a user would, in ``tmp_path`` (it writes runs/ there)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}  # one thread: the machine may be shared
    result = subprocess.run(
        [sys.executable, str(CLIENTS / script), "--env-id", env_id, *size_flags],
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
    # Gymnasium >= 1.0 writes no infos["final_info"], where the script reads its episodic
    # returns: the FinalInfo ids (next test) put them back.
    assert "episodic_return" not in stdout


@needs_clients
def test_cleanrl_ppo_logs_its_learning_curve_on_the_final_info_id(tmp_path):
    """The same run on the FinalInfo twin: every finished episode (4 of 60 steps in each
    environment's 256) is printed and written to TensorBoard as charts/episodic_return."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    stdout = run_cleanrl(
        "ppo.py", tmp_path, "--total-timesteps", "512", "--num-envs", "2", "--num-steps", "128",
        env_id=f"spikectl:{final_info_id(FLAT_ENV_ID)}",
    )  # fmt: skip
    printed = [line for line in stdout.splitlines() if "episodic_return=" in line]
    steps = [int(line.split(",")[0].removeprefix("global_step=")) for line in printed]
    assert steps == [120, 120, 242, 242, 364, 364, 486, 486]  # 2 per step; 60 + 1 apart
    events = EventAccumulator(str(next((tmp_path / "runs").rglob("events.out.tfevents.*"))))
    events.Reload()
    returns = events.Scalars("charts/episodic_return")
    assert [event.step for event in returns] == steps
    assert all(0.0 <= event.value <= 1.0 for event in returns)
    assert [event.value for event in events.Scalars("charts/episodic_length")] == [60] * 8


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
    # Given only the id, as SB3 users do (SB3 calls gymnasium.make on it), in the form that
    # works where spikectl was not imported (docs/ecosystem.md).
    model = PPO("MlpPolicy", IMPORTING_FLAT_ID, n_steps=256, batch_size=64, n_epochs=1, seed=0,
                device="cpu")  # fmt: skip
    model.learn(total_timesteps=512)
    assert model.num_timesteps == 512
    observation = np.zeros(206, dtype=np.float32)
    action, _ = model.predict(observation, deterministic=True)
    assert 0 <= int(action) <= 8


def test_the_flat_batched_env_names_gymnasiums_vector_env_as_a_direct_base():
    """What skrl's wrap_env reads to detect a Gymnasium vector env (the class's direct
    bases), with the method resolution order of the batched paper env under it."""
    assert gym.vector.VectorEnv in FlatNeuronControlVectorEnv.__bases__
    assert FlatNeuronControlVectorEnv.__mro__[1:] == NeuronControlVectorEnv.__mro__


@needs_skrl
def test_skrl_wrap_env_detects_the_batched_simulator_and_steps_it_as_it_is():
    """wrap_env's automatic detection picks skrl's Gymnasium wrapper in its vectorised
    form (single spaces, num_envs); its reset and steps are the env's own, as tensors."""
    import torch
    from skrl import config as skrl_config
    from skrl.envs.wrappers.torch import wrap_env
    from skrl.envs.wrappers.torch.gymnasium_envs import GymnasiumWrapper

    env = wrap_env(gym.make_vec(FLAT_ENV_ID, 8, **SMALL), verbose=False)
    reference = gym.make_vec(FLAT_ENV_ID, 8, **SMALL)
    assert isinstance(env, GymnasiumWrapper) and env.num_envs == 8
    assert env.observation_space == reference.single_observation_space
    assert env.action_space == gym.spaces.Discrete(9)
    observations, _ = env.reset()  # skrl seeds with its own key
    expected, _ = reference.reset(seed=skrl_config.torch.key)
    np.testing.assert_array_equal(observations.numpy(), expected)
    for actions in np.random.default_rng(0).integers(0, 9, size=(70, 8)):  # past an episode end
        stepped = env.step(torch.as_tensor(actions)[:, None])
        observations, rewards, terminated, truncated, _ = stepped
        expected, expected_rewards, expected_terminated, _, _ = reference.step(actions)
        np.testing.assert_array_equal(observations.numpy(), expected)
        np.testing.assert_allclose(rewards.numpy()[:, 0], expected_rewards, rtol=1e-6)
        np.testing.assert_array_equal(terminated.numpy()[:, 0], expected_terminated)
        assert not truncated.any()


@needs_skrl
def test_skrl_dqn_trains_on_the_batched_simulator(tmp_path):
    """skrl's DQN and SequentialTrainer on wrap_env(make_vec(flat id, 8)): 80 timesteps of
    8 environments, past an episode end, updating after 40."""
    import torch
    from skrl.agents.torch.dqn import DQN
    from skrl.envs.wrappers.torch import wrap_env
    from skrl.memories.torch import RandomMemory
    from skrl.trainers.torch import SequentialTrainer
    from skrl.utils.model_instantiators.torch import deterministic_model

    env = wrap_env(gym.make_vec(FLAT_ENV_ID, 8, **SMALL), verbose=False)

    def q_network():
        return deterministic_model(
            observation_space=env.observation_space, action_space=env.action_space,
            device="cpu", output="ACTIONS",
            network=[{"name": "net", "input": "OBSERVATIONS", "layers": [32],
                      "activations": "relu"}],
        )  # fmt: skip

    memory = RandomMemory(memory_size=200, num_envs=8, device="cpu")
    agent = DQN(
        models={"q_network": q_network(), "target_q_network": q_network()},
        memory=memory, observation_space=env.observation_space,
        action_space=env.action_space, device="cpu",
        cfg={"random_timesteps": 40, "learning_starts": 40, "batch_size": 32,
             "experiment": {"directory": str(tmp_path), "write_interval": 0,
                            "checkpoint_interval": 0}},
    )  # fmt: skip
    probe = {"observations": env.reset()[0]}  # the first observations, fixed

    def q_values():
        return agent.q_network.act(probe, role="q_network")[0].detach().clone()

    before = q_values()
    # skrl would close the environment at interpreter exit, logging to a stream pytest has
    # closed by then; the test closes it itself.
    trainer_cfg = {"timesteps": 80, "headless": True, "disable_progressbar": True,
                   "close_environment_at_exit": False}  # fmt: skip
    SequentialTrainer(env=env, agents=agent, cfg=trainer_cfg).train()
    env.close()
    assert len(memory) == 80 * 8
    rewards = memory.get_tensor_by_name("rewards")[:80]
    assert ((rewards >= 0) & (rewards <= 1)).all()
    assert before.shape == (8, 9)
    assert not torch.equal(q_values(), before)  # the updates after step 40 changed them


@needs_rllib
def test_rllib_ppo_trains_an_iteration_with_a_remote_env_runner_on_the_batched_simulator():
    """RLlib's PPO given the id, with a remote env runner (PPO's default is two): the
    runner is a new process that never imported spikectl, so the id carries the module
    prefix; the runner takes make_vec's batched entry point."""
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    config = (
        PPOConfig()
        .environment(IMPORTING_FLAT_ID, env_config=SMALL)
        .env_runners(
            num_env_runners=1,
            num_envs_per_env_runner=4,
            gym_env_vectorize_mode="vector_entry_point",
        )
        .training(train_batch_size_per_learner=480, minibatch_size=120, num_epochs=1)
    )
    algo = config.build_algo()
    try:
        remote = algo.env_runner_group.foreach_env_runner(
            lambda runner: (os.getpid(), type(runner.env.unwrapped).__name__),
            local_env_runner=False,
        )
        assert len(remote) == 1 and remote[0][0] != os.getpid()
        assert remote[0][1] == FlatNeuronControlVectorEnv.__name__
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 480
        assert 0.0 <= result["env_runners"]["episode_return_mean"] <= 1.0
    finally:
        algo.stop()
        ray.shutdown()
