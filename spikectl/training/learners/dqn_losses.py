"""The losses of recurrent double Q-learning over whole episodes (paper Appendix D).

The TD target is the double-Q target over ``n_step`` observed rewards (1 in the paper);
an auxiliary head predicting every neuron's next voltage may add its loss. The functions
take plain modules or one seed's view of stacked networks (inside ``torch.func.vmap``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from spikectl.agents import masked_q
from spikectl.agents.features import normalised_voltage
from spikectl.training.learners.dqn_config import DQNConfig
from spikectl.training.replay import EpisodeBatchArrays


def sequence_observations(batch: EpisodeBatchArrays, device: str) -> dict[str, torch.Tensor]:
    """Stored episodes → the networks' sequence input, observations 0..N (N + 1 steps)."""
    size, length = batch.actions.shape
    voltage = torch.as_tensor(batch.voltage, device=device)  # [B, N+1, n]
    actions = torch.as_tensor(batch.actions, device=device)  # [B, N]
    no_action = torch.full((size, 1), -1, dtype=torch.long, device=device)
    return {
        "voltage": voltage,
        "last_action": torch.cat([no_action, actions], dim=1),  # [B, N+1]
        "step": torch.arange(length + 1, device=device).expand(size, -1),  # [B, N+1]
        "target": torch.as_tensor(batch.targets, device=device)[:, None].expand(-1, length + 1),
        "pattern": torch.as_tensor(batch.patterns, device=device, dtype=torch.float32)[
            :, None
        ].expand(-1, length + 1, -1),  # [B, N+1, N]
    }


def n_step_targets(
    rewards: torch.Tensor, bootstrap: torch.Tensor, gamma: float, n_step: int
) -> torch.Tensor:
    """n-step TD targets of every step of whole episodes.

    ``rewards`` [B, N] are r_0 … r_{N-1}; ``bootstrap`` [B, N + 1] is the value of
    observation j (the one before step j), 0 at j = N because the episode terminates
    after step N - 1. For step t:

        td_target_t = Σ_{k<n, t+k<N} γ^k r_{t+k}  +  γ^n · bootstrap[t + n]

    with bootstrap beyond N read as 0. With n = 1 this is r_t + γ · bootstrap[t + 1].
    """
    steps = rewards.shape[1]
    discounts = gamma ** torch.arange(n_step, dtype=rewards.dtype, device=rewards.device)  # [n]
    windows = F.pad(rewards, (0, n_step - 1)).unfold(1, n_step, 1)  # [B, N, n]
    reward_sums = (windows * discounts).sum(dim=2)  # [B, N]
    future = F.pad(bootstrap, (0, n_step - 1))[:, n_step : n_step + steps]  # [B, N]
    return reward_sums + gamma**n_step * future


def training_losses(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    settings: DQNConfig,
    predictor: torch.nn.Module | None = None,
    device: str = "cpu",
    return_q_values: bool = False,
    return_features: bool = False,
) -> tuple[torch.Tensor, ...]:
    """The double-Q TD loss over every step of the sampled episodes and, with a
    ``predictor``, the auxiliary next-voltage loss (None without one); with
    ``return_q_values`` also the online Q-values [B, N + 1, n + 1] they were made from,
    with ``return_features`` (last) the encoder's features [B, N + 1, (n,) D]."""
    tensors = batch_tensors(batch, device)
    return losses_on_tensors(
        online, target, tensors, settings, predictor, return_q_values, return_features
    )


def batch_tensors(batch: EpisodeBatchArrays, device: str) -> dict[str, torch.Tensor]:
    """Sampled episodes as the tensors the losses read (``obs_seq`` is a nested dict)."""
    return {
        "obs_seq": sequence_observations(batch, device),
        "actions": torch.as_tensor(batch.actions, device=device),  # [B, N]
        "rewards": torch.as_tensor(batch.rewards, device=device),  # [B, N]
        "legal": torch.as_tensor(batch.action_masks, device=device)[:, None],  # [B, 1, n+1]
    }


def losses_on_tensors(
    online,
    target,
    tensors: dict,
    settings: DQNConfig,
    predictor=None,
    return_q_values: bool = False,
    return_features: bool = False,
) -> tuple[torch.Tensor, ...]:
    """:func:`training_losses` on :func:`batch_tensors`' output; the networks may be
    modules or one seed's view of stacked networks (inside vmap)."""
    obs_seq, actions, rewards, legal = (
        tensors["obs_seq"], tensors["actions"], tensors["rewards"], tensors["legal"]
    )  # fmt: skip
    # One online forward serves the taken-action values, the double-Q argmax and the
    # auxiliary prediction (which reads the encoder's features).
    q_values, features = online_forward(
        online, obs_seq, with_features=predictor is not None or return_features
    )
    q_taken = q_values[:, :-1].gather(2, (actions + 1)[..., None]).squeeze(2)  # [B, N]
    with torch.no_grad():
        # Double Q-learning: the online network picks the action at every observation,
        # the target network evaluates it; illegal actions are masked in the choice.
        best_actions = masked_q(q_values.detach(), legal).argmax(dim=2)  # [B, N+1]
        target_q_values, _ = target(obs_seq)  # [B, N+1, n+1]
        bootstrap = target_q_values.gather(2, best_actions[..., None]).squeeze(2)  # [B, N+1]
        bootstrap[:, -1] = 0.0  # observation N follows the terminal step
        td_target = n_step_targets(rewards, bootstrap, settings.gamma, settings.n_step)  # [B, N]
    td = td_regression_loss(q_taken, td_target, settings.loss)
    aux = None
    if predictor is not None:
        aux = next_voltage_loss(online, predictor, features, obs_seq, actions)
    return (
        (td, aux)
        + ((q_values,) if return_q_values else ())
        + ((features,) if return_features else ())
    )


def online_forward(
    online, obs_seq: dict[str, torch.Tensor], with_features: bool
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The sequence forward from a zero state: Q-values [B, N + 1, n + 1] and, when
    ``with_features`` (an auxiliary head reads them), the encoder's features
    [B, N + 1, (n,) D] (else None)."""
    if not with_features:
        q_values, _ = online(obs_seq)  # [B, N+1, n+1]
        return q_values, None
    features, _ = online.encode(obs_seq)  # [B, N+1, (n,) D]
    return online.q_values(features, obs_seq), features  # [B, N+1, n+1]


def td_regression_loss(q_taken: torch.Tensor, td_target: torch.Tensor, loss: str) -> torch.Tensor:
    """Mean over batch and steps of (q_taken - td_target)^2 (``"mse"``) or its Huber
    form with delta 1 (``"huber"``)."""
    if loss == "huber":
        return F.smooth_l1_loss(q_taken, td_target)
    return F.mse_loss(q_taken, td_target)


def next_voltage_loss(
    online, predictor, features: torch.Tensor, obs_seq: dict[str, torch.Tensor],
    actions: torch.Tensor,
) -> torch.Tensor:  # fmt: skip
    """The auxiliary loss: MSE of the predictor's every-neuron next normalised voltage,
    read from the features at t [B, N + 1, (n,) D] and the action at t [B, N]."""
    next_voltage = normalised_voltage(
        obs_seq["voltage"][:, 1:], online.v_rest_mV, online.v_threshold_mV
    )  # [B, N, n]
    predicted = predictor(features[:, :-1], actions)  # [B, N, n]
    return F.mse_loss(predicted, next_voltage)


def connectivity_loss(
    head: torch.nn.Module, features: torch.Tensor, target_inputs: torch.Tensor
) -> torch.Tensor:
    """The privileged auxiliary loss: cross-entropy of the head's every-step guess of each
    observed neuron's synapse onto the target, from the features [B, N + 1, (n,) D],
    against the training network's signs ``target_inputs`` [B, n] (-1, 0, +1), averaged
    over episodes, steps and neurons."""
    logits = head(features)  # [B, N+1, n, 3]
    classes = (target_inputs.long() + 1)[:, None].expand(-1, logits.shape[1], -1)  # [B, N+1, n]
    return F.cross_entropy(logits.flatten(0, 2), classes.flatten())


def td_loss(
    online: torch.nn.Module,
    target: torch.nn.Module,
    batch: EpisodeBatchArrays,
    settings: DQNConfig,
) -> torch.Tensor:
    """Double-Q TD loss over every step of the sampled episodes."""
    return training_losses(online, target, batch, settings)[0]


@torch.no_grad()
def soft_update(target: torch.nn.Module, online: torch.nn.Module, tau: float) -> None:
    """target <- tau * online + (1 - tau) * target."""
    for target_param, online_param in zip(target.parameters(), online.parameters(), strict=True):
        target_param.lerp_(online_param, tau)
