"""The public API as a user's typed code calls it: mypy checks this file (``mypy``, the
configuration in pyproject.toml) so that every name spikectl exports exists, is
annotated (a call to an unannotated function is an error here) and returns what its
documentation says. It is checked, never run: nothing happens at import.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

import spikectl
from spikectl.contexts import Context, ContextSet, make_validation_set
from spikectl.envs import ENV_ID, NeuronControlEnv, NeuronControlVectorEnv
from spikectl.envs.controller import Controller
from spikectl.envs.realtime import RealtimeReport, run_realtime
from spikectl.neuron import Extensions, NeuronParams, simulate
from spikectl.planning import (
    Composition,
    DecisionSettings,
    IdentifyAndPlan,
    Plan,
    named_composition,
    plan_episode,
)
from spikectl.wrappers import SB3CompatibleEnv, sb3_compatible, sb3_vec_env


def contexts_and_simulation() -> float:
    train, test = spikectl.make_splits(n_train=10, n_test=10, seed=0)
    train3, test3, validation = spikectl.make_splits(10, 10, n_val=10)
    more: ContextSet = make_validation_set(5, (train3, test3))
    context: Context = test[0]
    own: Context = spikectl.make_context(np.zeros((3, 3), dtype=np.int8), seed=0)
    path: Path = ContextSet([own]).save("own.npz")
    loaded: ContextSet = ContextSet.load(path)
    params = NeuronParams(capacitance_pF=25.0)
    voltages, spikes = simulate(context.weights, np.full(60, -1), params)
    shape: tuple[int, ...] = voltages.shape + spikes.shape
    actions, planned = plan_episode(context, width=64)
    return planned + len(loaded) + len(more) + len(validation) + len(train) + sum(shape)


def environments() -> float:
    env = NeuronControlEnv(split="test", extensions=Extensions(observation_noise_mV=1.0))
    observation, info = env.reset(seed=0)
    observation, reward, terminated, truncated, info = env.step(-1)
    envs = NeuronControlVectorEnv(num_envs=4)
    observations, infos = envs.reset(seed=0)
    made: gym.Env = gym.make(ENV_ID)
    wrapped: SB3CompatibleEnv = sb3_compatible(made)
    vectorised = sb3_vec_env(envs)
    mask: np.ndarray = wrapped.action_masks()
    return float(reward) + len(mask) + vectorised.num_envs


def controllers(env: NeuronControlEnv) -> float:
    planner: Controller = IdentifyAndPlan(
        composition=Composition("width16", decision=DecisionSettings(width=16)), seed=0
    )
    named: Controller = IdentifyAndPlan(composition=named_composition(None, 8))
    named.reset()
    planner.reset()
    observation, info = env.reset(seed=0)
    action: int = planner.act(observation, info)
    loaded: Controller = spikectl.load_controller("identify-and-plan", env=env)
    report: RealtimeReport = run_realtime(env, loaded, contexts=range(2), rate_hz=100.0)
    summary: dict[str, float] = report.summary()
    plans: list[Plan] = []
    return action + summary["mean_return"] + len(plans)


def a_bad_environment_variable() -> str:
    try:
        spikectl.environment_variables.check_environment({"NUMBA_NUM_THREADS": "0"})
    except spikectl.EnvironmentVariableError as error:
        return f"{error.name}={error.value}"
    return ""
