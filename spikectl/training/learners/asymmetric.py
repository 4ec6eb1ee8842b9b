"""The guided learner's privileged critic: asymmetric double Q-learning (Baisero, Daley &
Amato 2022, "Asymmetric DQN for partially observable reinforcement learning").

The agent's Q(h, a) reads only what it observes. Beside it a critic U(h, s, a), a network
of the same architecture, reads the same history and part of the true state s: each
observed neuron's synapse onto the target (G[i, target]: excites, inhibits or neither),
given to it as a certain ``belief`` input (the features the planner's belief would give,
``spikectl.planning.belief``: excites, inhibits, uncertainty 0). The critic learns by
double-Q TD on the agent's own greedy choice, and the agent regresses onto the critic
instead of bootstrapping on itself:

    u_target_t = Σ_{k<n} γ^k r_{t+k} + γ^n · U⁻(h_{t+n}, s, argmax_a Q(h_{t+n}, a))
    q_target_t = U⁻(h_t, s, a_t)

(U⁻ the critic's soft-updated copy). Because U also reads the history,
E[U(h, s, a) | h, a] is the agent's own Q(h, a): the agent's targets stay unbiased for
what it can see, unlike a critic of the state alone, while the critic, told which
neurons drive the target, can tell a good action from a lucky one. Only the agent acts,
is evaluated and is saved (``best_model.pt``); the critic lives in the checkpoint.
"""

from __future__ import annotations

import copy
import dataclasses

import torch

from spikectl.agents import make_agent, masked_q
from spikectl.seeds import CRITIC_STREAM, torch_seed
from spikectl.training.learners.dqn_losses import (
    n_step_targets,
    next_voltage_loss,
    online_forward,
    td_regression_loss,
)


def make_critic(config) -> tuple[torch.nn.Module, torch.nn.Module]:
    """The critic (the agent's architecture and sizes, plus the belief input) and its
    target copy, initialised from ``config.train.seed`` on a stream of its own (the
    configuration has refused an agent that cannot carry it,
    ``GuidedConfig.check_agent``)."""
    sizes = dataclasses.replace(config.agent.sizes, belief_in_input=True)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(torch_seed(config.train.seed, CRITIC_STREAM))
        critic = make_agent(
            config.agent.arch, config.env.n_observed, config.env.episode_length, sizes,
            params=config.env.params,
        )  # fmt: skip
    critic = critic.to(config.train.device)
    target = copy.deepcopy(critic)
    target.requires_grad_(False)
    return critic, target


def told_observations(
    obs_seq: dict[str, torch.Tensor], target_inputs: torch.Tensor
) -> dict[str, torch.Tensor]:
    """The agent's sequence input [B, N + 1, ...] plus the truth as a certain belief:
    ``belief`` [B, N + 1, n, 3] = (excites, inhibits, 0) from ``target_inputs`` [B, n]
    (-1, 0, +1: each observed neuron's synapse onto the target)."""
    steps = obs_seq["step"].shape[1]
    signs = target_inputs.to(obs_seq["pattern"].dtype)  # [B, n]
    belief = torch.stack(
        [(signs > 0).to(signs.dtype), (signs < 0).to(signs.dtype), torch.zeros_like(signs)],
        dim=-1,
    )  # [B, n, 3]
    return {**obs_seq, "belief": belief[:, None].expand(-1, steps, -1, -1)}  # [B, N+1, n, 3]


def asymmetric_losses(
    online: torch.nn.Module,
    critic: torch.nn.Module,
    critic_target: torch.nn.Module,
    tensors: dict,
    target_inputs: torch.Tensor,
    settings,
    predictor: torch.nn.Module | None = None,
    return_features: bool = False,
) -> tuple[torch.Tensor, ...]:
    """(the agent's regression loss onto the critic, the critic's TD loss, the auxiliary
    next-voltage loss or None, the agent's Q-values [B, N + 1, n + 1], and with
    ``return_features`` its encoder's features) over every step of the sampled episodes
    (``dqn_losses.batch_tensors``); ``target_inputs`` [B, n]."""
    obs_seq, actions, rewards, legal = (
        tensors["obs_seq"], tensors["actions"], tensors["rewards"], tensors["legal"]
    )  # fmt: skip
    q_values, features = online_forward(
        online, obs_seq, with_features=predictor is not None or return_features
    )  # [B, N+1, n+1]
    taken = (actions + 1)[..., None]  # [B, N, 1]
    q_taken = q_values[:, :-1].gather(2, taken).squeeze(2)  # [B, N]
    told = told_observations(obs_seq, target_inputs)
    u_values, _ = critic(told)  # [B, N+1, n+1]
    u_taken = u_values[:, :-1].gather(2, taken).squeeze(2)  # [B, N]
    with torch.no_grad():
        u_target_values, _ = critic_target(told)  # [B, N+1, n+1]
        # The critic values the agent's own greedy choice (illegal actions masked).
        greedy = masked_q(q_values.detach(), legal).argmax(dim=2)  # [B, N+1]
        bootstrap = u_target_values.gather(2, greedy[..., None]).squeeze(2)  # [B, N+1]
        bootstrap[:, -1] = 0.0  # observation N follows the terminal step
        u_target = n_step_targets(rewards, bootstrap, settings.gamma, settings.n_step)  # [B, N]
        q_target = u_target_values[:, :-1].gather(2, taken).squeeze(2)  # [B, N]
    agent_loss = td_regression_loss(q_taken, q_target, settings.loss)
    critic_loss = td_regression_loss(u_taken, u_target, settings.loss)
    aux = None
    if predictor is not None:
        aux = next_voltage_loss(online, predictor, features, obs_seq, actions)
    return (agent_loss, critic_loss, aux, q_values) + ((features,) if return_features else ())


__all__ = ["asymmetric_losses", "make_critic", "told_observations"]
