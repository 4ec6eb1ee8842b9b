"""A policy on the amortised belief (issue 61): a small network that reads the belief over
the target's inputs and the neurons' timing, and is trained to act as identify-and-plan
acts, on its own states (DAgger).

:class:`~spikectl.agents.amortised_controller.AmortisedController` decides from the
belief by a fixed rule (stimulate the likeliest input that can land on a wanted step,
probe on quiet stretches). :class:`BeliefPolicyController` keeps its belief and feature
tracking and replaces the rule by :class:`BeliefPolicyNet`: each neuron is a token with
shared weights (its belief, whether a stimulation lands in time, its refractoriness and
potential, the step's pattern ahead), scored by one MLP; the do-nothing score reads the
step's facts and the neurons' pooled embeddings. So it runs on any n and permuting the
neurons permutes its scores. It is trained by imitation of identify-and-plan's actions
on the states the policy itself reaches (``lab/results/belief-policy``), and acts with
the legal action of highest score, in NumPy (:class:`PolicyKernel`, no PyTorch at
decision time).

A belief policy's weights file is a ``.pt`` state dict holding the belief's tensors
under ``belief.`` and the policy's under ``policy.``; ``spikectl.load_controller`` plays
it (:func:`load_belief_policy`), and refuses anything else with one
:class:`~spikectl.agents.amortised_controller.BeliefWeightsError` line.

Shapes in comments: B batch, n neurons, D features, H width.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from torch import nn

from spikectl.agents.amortised_belief import AmortisedBelief
from spikectl.agents.amortised_controller import (
    AmortisedController,
    BeliefWeightsError,
    belief_from_state,
    read_state_dict,
)
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING

AHEAD_STEPS = 6
"""Steps of the target pattern the policy reads, from the next one on: the release
interval and one more (a probe now is rested again by then)."""
NEURON_FEATURES = ("none", "excitatory", "inhibitory", "legal", "can_land", "refractory",
                   "rested", "since_release", "potential", "is_target", "prior",
                   "rule_choice")  # fmt: skip
"""A neuron's own inputs, in column order."""
STEP_FEATURES = tuple(f"wanted_{k + 1}" for k in range(AHEAD_STEPS)) + (
    "episode_fraction", "target_potential", "target_refractory", "best_landing",
    "best_input", "expected_inputs", "rule_nothing",
)  # fmt: skip
"""The step's inputs, the same for every neuron, in column order."""
N_POLICY_FEATURES = len(NEURON_FEATURES) + len(STEP_FEATURES)
N_STEP_FEATURES = len(STEP_FEATURES)


def policy_features(probabilities: np.ndarray, legal: np.ndarray, can_land: np.ndarray,
                    tracker: Any, pattern: np.ndarray, step: int, params: NeuronParams,
                    rule_action: int) -> np.ndarray:  # fmt: skip
    """float32 [n, D] the policy's input at one step: each neuron's row of
    :data:`NEURON_FEATURES` followed by the step's :data:`STEP_FEATURES`.

    ``probabilities`` [n, 3] the belief over G[i, target] (none, excitatory, inhibitory;
    the target's own row none), ``legal`` and ``can_land`` [n] bool, ``tracker`` the
    controller's :class:`~spikectl.agents.amortised_kernel.BeliefFeatureTracker`,
    ``pattern`` [T] bool, ``step`` the step about to be acted on, ``rule_action`` the
    amortised controller's fixed rule's action there (-1: nothing), so that the policy
    starts from a rule it can copy exactly."""
    n, target = probabilities.shape[0], tracker.target
    interval = float(params.min_release_interval_steps)
    span = float(params.v_spike_mV - params.v_rest_mV)
    refractory = tracker.refractory_left / max(float(params.refractory_steps), 1.0)
    potential = (tracker.after_reset - params.v_rest_mV) / span
    out = np.zeros((n, N_POLICY_FEATURES), dtype=np.float32)
    out[:, 0:3] = probabilities
    out[:, 3] = legal
    out[:, 4] = can_land
    out[:, 5] = refractory
    out[:, 6] = tracker.since + 1 >= interval
    out[:, 7] = np.minimum(tracker.since, interval) / interval
    out[:, 8] = potential
    out[target, 9] = 1.0
    out[:, 10] = tracker.prior
    if rule_action != DO_NOTHING:
        out[rule_action, 11] = 1.0
    ahead = pattern[step + 1 : step + 1 + AHEAD_STEPS]
    shared = out[0, len(NEURON_FEATURES):]  # [G], then copied to every neuron
    shared[: ahead.shape[0]] = ahead
    excitatory = probabilities[:, 1]
    shared[AHEAD_STEPS:] = (
        step / max(pattern.shape[0] - 1, 1), potential[target], refractory[target],
        excitatory[can_land].max(initial=0.0), excitatory.max(), excitatory.sum() / 4.0,
        rule_action == DO_NOTHING,
    )  # fmt: skip
    out[1:, len(NEURON_FEATURES):] = shared
    return out


class BeliefPolicyNet(nn.Module):
    """Scores every action from :func:`policy_features`: one shared MLP per neuron
    (its score to stimulate it) and a do-nothing score from the step's features and the
    neurons' mean- and max-pooled embeddings.

    Args:
        width: the hidden width H.
    """

    def __init__(self, width: int = 64) -> None:
        super().__init__()
        self.width = width
        self.neuron = nn.Sequential(nn.Linear(N_POLICY_FEATURES, width), nn.GELU("tanh"),
                                    nn.Linear(width, width), nn.GELU("tanh"))  # fmt: skip
        self.stimulate = nn.Linear(width, 1)
        self.nothing = nn.Sequential(nn.Linear(N_STEP_FEATURES + 2 * width, width),
                                     nn.GELU("tanh"), nn.Linear(width, 1))  # fmt: skip

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """features [B, n, D] -> scores [B, n + 1] (do nothing first; not masked)."""
        hidden = self.neuron(features)  # [B, n, H]
        stimulate = self.stimulate(hidden).squeeze(-1)  # [B, n]
        pooled = torch.cat([features[:, 0, len(NEURON_FEATURES):], hidden.mean(dim=1),
                            hidden.amax(dim=1)], dim=-1)  # [B, G + 2H]  # fmt: skip
        return torch.cat([self.nothing(pooled), stimulate], dim=-1)


def _gelu(x: np.ndarray) -> np.ndarray:
    """PyTorch's GELU with ``approximate="tanh"``, in NumPy."""
    return 0.5 * x * (1.0 + np.tanh(0.7978845608028654 * (x + 0.044715 * x**3)))


class PolicyKernel:
    """:class:`BeliefPolicyNet`'s forward for one step in NumPy (float64): ``scores(features
    [n, D]) -> [n + 1]``, equal to the PyTorch forward within float32 rounding."""

    def __init__(self, net: BeliefPolicyNet) -> None:
        state = {key: value.detach().cpu().numpy().astype(np.float64)
                 for key, value in net.state_dict().items()}  # fmt: skip
        self.layers = [(state[f"neuron.{k}.weight"].T.copy(), state[f"neuron.{k}.bias"])
                       for k in (0, 2)]  # fmt: skip
        self.stimulate = (state["stimulate.weight"][0], float(state["stimulate.bias"][0]))
        self.nothing = [(state[f"nothing.{k}.weight"].T.copy(), state[f"nothing.{k}.bias"])
                        for k in (0, 2)]  # fmt: skip

    def scores(self, features: np.ndarray) -> np.ndarray:
        hidden = features.astype(np.float64)  # [n, D]
        for weight, bias in self.layers:
            hidden = _gelu(hidden @ weight + bias)  # [n, H]
        stimulate = hidden @ self.stimulate[0] + self.stimulate[1]  # [n]
        pooled = np.concatenate([features[0, len(NEURON_FEATURES):], hidden.mean(axis=0),
                                 hidden.max(axis=0)])  # [G + 2H]  # fmt: skip
        (w1, b1), (w2, b2) = self.nothing
        nothing = _gelu(pooled @ w1 + b1) @ w2 + b2  # [1]
        return np.concatenate([nothing, stimulate])


class BeliefPolicyController(AmortisedController):
    """The amortised belief's controller with :class:`BeliefPolicyNet` as its decision
    rule (module docstring): the legal action of highest score, the first of equal
    maxima.

    Args:
        belief: as :class:`~spikectl.agents.amortised_controller.AmortisedController`'s.
        net: the trained :class:`BeliefPolicyNet` (or a :class:`PolicyKernel`).
        params: the neuron model (None: the paper's).
    """

    def __init__(self, belief: Any, net: Any, params: NeuronParams | None = None) -> None:
        super().__init__(belief, params)
        self.policy = PolicyKernel(net) if isinstance(net, BeliefPolicyNet) else net
        self.last_features = np.zeros((0, N_POLICY_FEATURES), dtype=np.float32)

    def spawn(self, index: int) -> BeliefPolicyController:
        """A copy for sub-environment ``index`` (shared weights, its own belief state)."""
        return BeliefPolicyController(copy.copy(self.kernel), self.policy, self.params)

    def features(self, pattern: np.ndarray, step: int, mask: np.ndarray) -> np.ndarray:
        """float32 [n, D] this step's :func:`policy_features` (kept as ``last_features``)."""
        legal = mask[1:]
        can_land = self.can_land(legal)
        self.last_features = policy_features(self.probabilities, legal, can_land,
                                             self.tracker, pattern, step, self.params,
                                             self.rule_action(pattern, step, can_land))  # fmt: skip
        return self.last_features

    def decide(self, pattern: np.ndarray, step: int, mask: np.ndarray) -> int:
        scores = self.policy.scores(self.features(pattern, step, mask))  # [n + 1]
        return int(np.argmax(np.where(mask, scores, -np.inf))) + DO_NOTHING


def is_belief_policy_state(state: Mapping[str, Any]) -> bool:
    """Whether a loaded state dict is meant as a belief policy's (it has ``policy.``
    tensors; :func:`load_belief_policy` checks the rest)."""
    return any(isinstance(key, str) and key.startswith("policy.") for key in state)


def save_belief_policy(belief: nn.Module, net: BeliefPolicyNet, path: str | os.PathLike) -> None:
    """Write ``belief`` and ``net`` as one belief policy's weights file (atomically)."""
    state = {f"belief.{key}": value for key, value in belief.state_dict().items()}
    state.update({f"policy.{key}": value for key, value in net.state_dict().items()})
    partial = f"{os.fspath(path)}.partial"
    torch.save(state, partial)
    os.replace(partial, path)


def read_belief_policy(
    path: str | os.PathLike, state: Mapping[str, Any] | None = None
) -> tuple[AmortisedBelief, BeliefPolicyNet]:
    """(the belief, the policy net) a belief policy's weights file holds, checked
    (``state``: the file's state dict where it is already read)."""
    state = read_state_dict(path) if state is None else state
    parts = {prefix: {key[len(prefix):]: value for key, value in state.items()
                      if isinstance(key, str) and key.startswith(prefix)}
             for prefix in ("belief.", "policy.")}  # fmt: skip
    if not parts["belief."] or not parts["policy."]:
        raise BeliefWeightsError(f"{path} does not hold a belief policy's weights (it needs "
                                 "both belief. and policy. tensors)")  # fmt: skip
    belief, policy = belief_from_state(path, parts["belief."]), parts["policy."]
    first = policy.get("neuron.0.weight")
    if not isinstance(first, torch.Tensor) or first.ndim != 2 \
            or first.shape[1] != N_POLICY_FEATURES:  # fmt: skip
        raise BeliefWeightsError(f"{path} does not hold a belief policy's weights (no "
                                 f"policy.neuron.0.weight of [width, {N_POLICY_FEATURES}])")
    net = BeliefPolicyNet(int(first.shape[0]))
    try:
        net.load_state_dict(policy)
    except (RuntimeError, ValueError) as error:
        raise BeliefWeightsError(f"{path}: the policy's tensors do not fit a belief policy "
                                 f"of width {first.shape[0]}: {str(error).splitlines()[0]}"
                                 ) from None  # fmt: skip
    if not all(bool(torch.isfinite(value).all()) for value in policy.values()):
        raise BeliefWeightsError(f"{path} holds NaN or infinite weights")
    return belief, net.eval()


def load_belief_policy(
    path: str | os.PathLike, params: NeuronParams | None = None,
    state: Mapping[str, Any] | None = None,
) -> BeliefPolicyController:  # fmt: skip
    """The controller a belief policy's weights file holds (:func:`read_belief_policy`)."""
    return BeliefPolicyController(*read_belief_policy(path, state), params)
