"""K seeds of the double-Q learner as one stacked computation (``--stacked``).

The online, target and auxiliary networks of all seeds are stacked along a leading seed
dimension (``spikectl.agents.stacked``); every acting step, forward, backward and Adam
step serves all K at once (``torch.func.vmap``). Each seed keeps what it has alone: its
replay buffer, the run's generator (drawn in the same order), its epsilon schedule,
target network and auxiliary head, its own gradient-norm clip and Adam moments (Adam is
elementwise, so one Adam on stacked parameters is K independent Adams). The loss
backpropagated is the sum of the seeds' losses, whose gradients never mix.

The maths is the looped group's; the numbers differ from it in floating-point rounding
(batched kernels sum in another order, the stacked LSTM is written out where a plain
one is nn.LSTM's fused kernel), so after enough updates a stacked seed parts from the
seed alone as two thread counts do. It pays on a GPU, where one small update leaves the
device idle (docs/benchmarks.md), not on a CPU.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from spikectl.agents import greedy_action, make_agent
from spikectl.agents.stacked import StackedNetworks
from spikectl.envs.rollout import EpisodeBatch
from spikectl.training.cuda_graphs import (
    CapturedCall,
    eager_optimizer_state,
    make_capturable,
    update_snapshot,
)
from spikectl.training.learners.dqn import DQNLearner, losses_on_tensors
from spikectl.training.learners.protocol import LossDiverged
from spikectl.training.learners.q_learning import batch_tensors, explore, set_learning_rate
from spikectl.training.stacked_update import clip_grad_norm_per_seed, stack_seeds


class StackedDQN:
    """A LearnerGroup of K double-Q learners stacked into one computation."""

    metric_fields = DQNLearner.metric_fields

    def __init__(self, configs, train_sets, rngs: list[np.random.Generator]) -> None:
        # Each seed's learner builds its networks, buffer and counters exactly as alone;
        # the group then computes with their stacked parameters.
        self.seeds = [
            DQNLearner(config, train_set, rng)
            for config, train_set, rng in zip(configs, train_sets, rngs, strict=True)
        ]
        self.configs, self.size = configs, len(configs)
        self.settings, self.device = configs[0].learner, configs[0].train.device
        self.online = StackedNetworks([seed.network for seed in self.seeds])
        self.target = StackedNetworks([seed.target for seed in self.seeds], trainable=False)
        predictors = [seed.predictor for seed in self.seeds]
        self.predictor = None if predictors[0] is None else StackedNetworks(predictors)
        self.trained = self.online.parameters() + (
            self.predictor.parameters() if self.predictor is not None else []
        )
        self.optimizer = torch.optim.Adam(self.trained, lr=self.settings.learning_rate)
        # CUDA graphs (spikectl.training.cuda_graphs), captured at the first update / step.
        self.cuda_graphs = configs[0].train.cuda_graphs and torch.device(self.device).type == "cuda"
        self._captured_update: CapturedCall | None = None
        self._captured_steps: dict[tuple, CapturedCall] = {}
        self.batched_losses = torch.func.vmap(
            self._seed_losses, in_dims=(0, 0, 0 if self.predictor is not None else None, 0)
        )

    def _seed_losses(self, online_params, target_params, predictor_params, tensors):
        td, aux = losses_on_tensors(
            self.online.bound(online_params), self.target.bound(target_params), tensors,
            self.settings,
            None if self.predictor is None else self.predictor.bound(predictor_params),
        )  # fmt: skip
        return td, (torch.zeros_like(td) if aux is None else aux)

    def collection_policy(self, episode: int) -> StackedPolicy:
        epsilon = self.seeds[0].epsilon(episode)
        return StackedPolicy(self, epsilon, [seed.rng for seed in self.seeds])

    def observe(self, episodes: list[EpisodeBatch], contexts: list[np.ndarray]) -> None:
        for seed, seed_episodes, seed_contexts in zip(self.seeds, episodes, contexts, strict=True):
            seed.observe(seed_episodes, seed_contexts)

    def update(self, episode: int) -> None:
        settings = self.settings
        if len(self.seeds[0].replay) < max(settings.learning_starts, 1):
            return
        total = self.seeds[0].total_episodes
        set_learning_rate(self.optimizer, settings.learning_rate_at(episode, total))
        for _ in range(settings.updates_per_round):
            tensors = stack_seeds([
                batch_tensors(seed.replay.sample(settings.batch_size, seed.rng), self.device)
                for seed in self.seeds
            ])  # fmt: skip  # every tensor [K, B, ...]
            if self.cuda_graphs:
                if self._captured_update is None:
                    self._captured_update = self._capture_update(tensors)
                # The step is in the graph, so a diverged loss is caught after it; the run
                # stops and keeps its last checkpoint either way.
                td_values, aux_values = self._checked_losses(*self._captured_update(tensors))
            else:
                td, aux = self._losses(tensors)
                td_values, aux_values = self._checked_losses(td, aux)  # the weights stay finite
                self._step(td, aux)
            for seed, td_k, aux_k in zip(self.seeds, td_values, aux_values, strict=True):
                seed.updates += 1
                seed.loss_sum += td_k
                seed.aux_loss_sum += aux_k
                seed.loss_count += 1

    def _losses(self, tensors: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """Every seed's TD and auxiliary losses, each [K]."""
        return self.batched_losses(
            self.online.params, self.target.params,
            self.predictor.params if self.predictor is not None else None, tensors,
        )  # fmt: skip

    def _total(self, td: torch.Tensor, aux: torch.Tensor) -> torch.Tensor:
        return td if self.predictor is None else td + self.settings.aux_voltage_weight * aux

    @torch.no_grad()
    def _checked_losses(self, td: torch.Tensor, aux: torch.Tensor) -> tuple[list, list]:
        """The seeds' TD and auxiliary losses on the host, in one transfer (the update's
        only sync); LossDiverged for the first seed whose total loss is not finite."""
        td_values, aux_values, totals = torch.stack((td, aux, self._total(td, aux))).tolist()
        for k, total in enumerate(totals):
            if not math.isfinite(total):
                raise LossDiverged(total, self.seeds[k].updates + 1, k)
        return td_values, aux_values

    def _step(self, td: torch.Tensor, aux: torch.Tensor) -> None:
        """Backward, per-seed clip, Adam and the soft target update (no host sync)."""
        self.optimizer.zero_grad(set_to_none=True)
        self._total(td, aux).sum().backward()  # seeds' gradients stay apart: d(sum)/d(l_k) = 1
        if self.settings.max_grad_norm > 0:
            clip_grad_norm_per_seed(self.trained, self.settings.max_grad_norm)
        self.optimizer.step()
        with torch.no_grad():
            for name in self.target.names:
                self.target.params[name].lerp_(self.online.params[name], self.settings.tau)

    def _update_and_losses(self, tensors: dict) -> tuple[torch.Tensor, torch.Tensor]:
        td, aux = self._losses(tensors)
        self._step(td, aux)
        return td.detach(), aux.detach()

    def _capture_update(self, tensors: dict) -> CapturedCall:
        make_capturable(self.optimizer, self.device)
        changed = self.trained + self.target.parameters()
        return CapturedCall(
            self._update_and_losses, (tensors,),
            snapshot=lambda: update_snapshot(changed, self.optimizer),
        )  # fmt: skip

    @torch.no_grad()
    def acting_step(self, obs: dict, state: tuple) -> tuple[torch.Tensor, tuple]:
        """Every seed's step forward on [K, E, ...] observations: (Q-values [K, E, n+1],
        next state). Captured in a CUDA graph per input shape where graphs are on; its
        outputs are then the graph's, valid until the next step."""
        if not self.cuda_graphs:
            return self.online.call("step", obs, state)
        shape = tuple(obs["voltage"].shape)
        if shape not in self._captured_steps:
            # Captured under this method's no_grad, so the graph records no autograd work.
            self._captured_steps[shape] = CapturedCall(
                functools.partial(self.online.call, "step"), (obs, state)
            )
        return self._captured_steps[shape](obs, state)

    def network(self, seed: int) -> torch.nn.Module:
        """Seed ``seed``'s current weights in a plain network (nn.LSTM and all), so it is
        scored exactly as ``spikectl evaluate`` scores its model.pt."""
        config = self.configs[seed]
        network = make_agent(
            config.agent.arch, config.env.n_observed, config.env.episode_length,
            config.agent.sizes, params=config.env.params,
        )  # fmt: skip
        network.load_state_dict(self.online.state_dict(seed))
        return network.to(self.device)

    def updates(self, seed: int) -> int:
        return self.seeds[seed].updates

    def row_metrics(self, seed: int, episode: int) -> dict[str, float]:
        return self.seeds[seed].row_metrics(episode)

    def progress(self, episode: int) -> dict[str, str]:
        return self.seeds[0].progress(episode)

    def state_dict(self) -> dict[str, Any]:
        return {
            "stacked": {
                "online": self.online.stacked_state(),
                "target": self.target.stacked_state(),
                "predictor": None if self.predictor is None else self.predictor.stacked_state(),
                "optimizer": eager_optimizer_state(self.optimizer),
            },
            "seeds": [_counters_and_replay(seed) for seed in self.seeds],
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        stacked = state["stacked"]
        self.online.load_stacked_state(stacked["online"])
        self.target.load_stacked_state(stacked["target"])
        if self.predictor is not None:
            self.predictor.load_stacked_state(stacked["predictor"])
        self.optimizer.load_state_dict(stacked["optimizer"])
        self._captured_update = None  # the graph read the optimizer state just replaced
        for seed, entry in zip(self.seeds, state["seeds"], strict=True):
            seed.load_counters_and_replay(entry)


def _counters_and_replay(seed: DQNLearner) -> dict[str, Any]:
    state = seed.state_dict()
    return {key: state[key] for key in DQNLearner.counter_and_replay_keys}


class StackedPolicy:
    """Acts for K seeds at once: the sub-environments hold K blocks of E episodes, block k
    played by seed k's online network with seed k's epsilon and generator."""

    def __init__(self, group: StackedDQN, epsilon: float, rngs) -> None:
        self.group, self.epsilon, self.rngs = group, epsilon, rngs
        self.state = None

    @torch.no_grad()
    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        group, K, device = self.group, self.group.size, self.group.device
        obs = {
            key: torch.as_tensor(
                np.asarray(observations[key]).astype(
                    np.float32 if key in ("voltage", "pattern") else np.int64, copy=False
                ),
                device=device,
            ).unflatten(0, (K, -1))  # [K, E, ...]
            for key in ("voltage", "target", "pattern", "step", "last_action")
        }
        if self.state is None:
            E, n = obs["voltage"].shape[1:]
            state = group.online.template.initial_state(E, n, device=device)
            self.state = tuple(s.expand(K, *s.shape).clone() for s in state)  # [K, E, ...]
        q_values, self.state = group.acting_step(obs, self.state)  # [K, E, n+1]
        legal = torch.as_tensor(action_mask, device=q_values.device).unflatten(0, (K, -1))
        greedy = greedy_action(q_values, legal).cpu().numpy()  # [K, E]
        if self.epsilon <= 0:
            return greedy.reshape(-1)
        masks = action_mask.reshape(K, -1, action_mask.shape[-1])  # [K, E, n+1]
        return np.concatenate([
            explore(greedy[k], masks[k], self.epsilon, self.rngs[k],
                    group.settings.explore_do_nothing)
            for k in range(K)
        ])  # fmt: skip
