"""A trained network as a greedy controller, with the inputs it reads computed beside it,
and its greedy evaluation during training: the training loop's scores."""

from __future__ import annotations

import numpy as np
import torch

from spikectl.agents.greedy import GreedyController
from spikectl.envs.rollout import run_episodes
from spikectl.envs.vector_env import NeuronControlVectorEnv
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning.advice import PlannerAdvice
from spikectl.planning.belief import BeliefInputs, TargetInputBelief


def belief_input(
    network: torch.nn.Module, params: NeuronParams | None, extensions: Extensions | None
) -> BeliefInputs | None:
    """What computes ``network``'s ``belief`` input on an environment with neuron model
    ``params`` and ``extensions`` (None: the paper's): the planner's belief
    (``AgentSizes.belief_in_input``, under the extensions' measurement noise), then its
    advice (``advice_in_input``, the named identify-and-plan on that environment); None
    for a network that reads neither."""
    sizes = getattr(network, "sizes", None)
    if sizes is None or not sizes.reads_belief:
        return None
    params = params or NeuronParams()
    noise_mV = 0.0 if extensions is None else extensions.observation_noise_mV
    parts: list[TargetInputBelief | PlannerAdvice] = []
    if sizes.belief_in_input:
        parts.append(TargetInputBelief(params, noise_mV))
    if sizes.advice_in_input:
        parts.append(PlannerAdvice(params, extensions))
    return BeliefInputs(parts)


def greedy_controller(
    network: torch.nn.Module,
    params: NeuronParams | None,
    extensions: Extensions | None,
    device: str = "cpu",
    per_environment: bool = False,
) -> GreedyController:
    """``GreedyController(network)`` for an environment with ``params`` and ``extensions``:
    every route that plays a trained network (training, ``spikectl evaluate``,
    ``spikectl benchmark``, ``load_controller``) builds it here, so a network that reads
    the belief gets it everywhere."""
    return GreedyController(
        network, device, per_environment, belief=belief_input(network, params, extensions)
    )


def greedy_returns(
    network: torch.nn.Module, env: NeuronControlVectorEnv, device: str, seed: int
) -> float:
    """Mean greedy return over every context of the environment's set (one batch); the
    environment's own draws (noise, ...) start from ``seed`` every time."""
    network.eval()
    env.reset(seed=seed)
    controller = greedy_controller(network, env.params, env.extensions, device)
    episodes = run_episodes(env, np.arange(env.num_envs), controller)
    network.train()
    return float(episodes.returns.mean())
