"""A controller on the amortised belief (issue 61): it reads the belief over the target's
inputs every step and stimulates the neuron most likely to make the target spike when
the pattern wants a spike next.

Each step it turns the new observation into the belief's input row
(:class:`~spikectl.agents.amortised_kernel.BeliefFeatureTracker`), runs one step of the
trained belief in NumPy (:class:`~spikectl.agents.amortised_kernel.BeliefKernel`) and
decides by :func:`choose_action`: when the pattern wants the target to spike at the next
step, stimulate the neuron with the highest P(G[i, target] = +1) among those whose
stimulation can land then (not refractory, its synapses rested: the vesicle rule,
docs/model.md), under ``rule="greedy"``; under ``rule="thompson"`` (posterior sampling)
the same among the neurons whose class, drawn from the belief, is excitatory. A wanted
step is a free probe: a neuron that was not an input is seen not to be one, at no cost
against doing nothing, and the belief moves on. On a quiet stretch (no spike wanted
for the release interval ahead) while no input is yet likely (``probe_below``) it
probes the likeliest neuron that can land, at the cost of an unwanted spike when it is one, so that
the next wanted step finds an input rested. Otherwise it does nothing.

It reads the paper's observation model (potentials seen exactly, no latency, every
neuron observed), as the belief was trained: under the extensions that change it, its
features mean something else. It plans with the target's column alone: it never uses
cascades through other neurons
(identify-and-plan's beam search plans with all of G, docs/results/amortised-controller
measures what that costs). The belief's weights come from a file
(``lab/results/amortised-belief/train.py`` writes one); :func:`load_belief` refuses
anything else with one :class:`BeliefWeightsError` line.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spikectl.agents.amortised_belief import N_FEATURES, AmortisedBelief
from spikectl.agents.amortised_kernel import BeliefFeatureTracker, BeliefKernel, target_prior
from spikectl.contexts.generation import EXCITATORY_PROBABILITY
from spikectl.envs.controller import ControllerInputError, check_controller_input
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING

RULES = ("greedy", "thompson")
"""How :func:`choose_action` picks among the neurons that can land a spike in time."""
PROBE_BELOW = 0.5
"""Probe on quiet stretches while no neuron is an input this likely (chosen on the
``n16`` and ``n32`` validation sets among 0, 0.5, 0.8 and 0.95: 0.5, 0.8 and 0.95 score
within 0.003 of each other, 0.02-0.03 above 0; docs/results/amortised-controller)."""
PROBE_FLOOR = 0.02
"""A neuron less likely than this to be an input is not worth a probe (the generator's
base rate beyond 8 neurons apart is below it)."""
BELIEF_HEADS = 4
"""The attention heads of the trained beliefs (a state dict does not record them)."""


class BeliefWeightsError(ValueError):
    """A belief weights file that is missing, unreadable, or not an
    :class:`~spikectl.agents.amortised_belief.AmortisedBelief`'s state dict."""


def load_belief(path: str | os.PathLike, heads: int = BELIEF_HEADS) -> AmortisedBelief:
    """The trained belief saved at ``path`` (``torch.save(model.state_dict())``, as
    ``lab/results/amortised-belief/train.py`` writes it), on CPU, weights only; its width
    and layer count are read from the tensors' shapes."""
    return belief_from_state(path, read_state_dict(path), heads)


def read_state_dict(path: str | os.PathLike) -> dict:
    """The state dict a weights file holds (CPU tensors, weights only)."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise BeliefWeightsError(f"{path}: no amortised belief weights file there "
                                 "(lab/results/amortised-belief/train.py --out DIR writes "
                                 "DIR/belief.pt)")  # fmt: skip
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises many kinds for a damaged file
        text = str(error).strip()
        first = text.splitlines()[0] if text else type(error).__name__
        raise BeliefWeightsError(
            f"{path} is not a readable PyTorch weights file: {first}"
        ) from None
    if not isinstance(state, dict):
        raise BeliefWeightsError(f"{path} does not hold a state dict")
    return state


def belief_from_state(path: str | os.PathLike, state: Mapping[str, Any],
                      heads: int = BELIEF_HEADS) -> AmortisedBelief:  # fmt: skip
    """The belief ``state`` (read from ``path``, named in messages) holds, checked."""
    import torch

    encode = state.get("encode.0.weight")
    if not isinstance(encode, torch.Tensor) or encode.ndim != 2 or encode.shape[1] != N_FEATURES:
        raise BeliefWeightsError(f"{path} does not hold an amortised belief's weights (no "
                                 f"encode.0.weight of [width, {N_FEATURES}])")  # fmt: skip
    width = int(encode.shape[0])
    layers = len({key.split(".")[1] for key in state if key.startswith("mix.")})
    try:
        model = AmortisedBelief(width, heads, layers)
        model.load_state_dict(state)
    except (RuntimeError, ValueError) as error:
        first = str(error).splitlines()[0]
        raise BeliefWeightsError(
            f"{path} does not fit an amortised belief of width {width}, {layers} mixing "
            f"layers: {first}"
        ) from None
    if not all(bool(torch.isfinite(value).all()) for value in state.values()):
        raise BeliefWeightsError(f"{path} holds NaN or infinite weights")
    return model.eval()


def choose_action(
    excitatory: np.ndarray,
    can_land: np.ndarray,
    ahead: np.ndarray,
    rule: str = "greedy",
    rng: np.random.Generator | None = None,
    probe_below: float = PROBE_BELOW,
) -> int:
    """The action for one step.

    Args:
        excitatory: [n] P(G[i, target] = +1) (0 for the target).
        can_land: [n] bool: legal, and stimulated now it releases at the next step.
        ahead: bool, the pattern's next steps (from the next one on, up to the release
            interval): whether the target should spike then.
        rule: ``"greedy"``: on a wanted next step, the most probable input that can
            land; ``"thompson"``: the most probable among those whose class, drawn from
            the belief with ``rng``, is excitatory.
        rng: the generator of ``thompson``'s draws.
        probe_below: when nothing is wanted for the whole of ``ahead`` and no neuron is
            an input with at least this probability, probe the likeliest one that can
            land, if it is at least :data:`PROBE_FLOOR` likely (``probe_below`` 0:
            never): the target's answer identifies it, and it is rested again by the
            next wanted step.

    Ties go to the lower index; nothing to stimulate is -1.
    """
    score = np.where(can_land, excitatory, -1.0)  # [n]
    if ahead.size == 0 or not ahead[0]:
        best = int(np.argmax(score))
        probe = (not ahead.any() and excitatory.max() < probe_below
                 and score[best] >= PROBE_FLOOR)  # fmt: skip
        return best if probe else DO_NOTHING
    if rule == "thompson":
        score = np.where(rng.random(excitatory.shape) < excitatory, score, -1.0)
    best = int(np.argmax(score))
    return best if score[best] > 0.0 else DO_NOTHING


class AmortisedController:
    """Greedy or posterior-sampling control on the amortised belief (module docstring).

    Args:
        belief: a trained :class:`~spikectl.agents.amortised_belief.AmortisedBelief`
            (:func:`load_belief`), or any object with ``reset(prior [n])`` and
            ``step(features [n, F]) -> logits [n, 3]`` (a
            :class:`~spikectl.agents.amortised_kernel.BeliefKernel`'s interface).
        params: the neuron model (None: the paper's).
        rule: one of :data:`RULES`.
        seed: seeds ``thompson``'s draws (one generator per controller; :meth:`spawn`'s
            copies get ``seed + index``).
        probe_below: :func:`choose_action`'s (0: probe only on wanted steps).
    """

    def __init__(self, belief: Any, params: NeuronParams | None = None, rule: str = "greedy",
                 seed: int = 0, probe_below: float = PROBE_BELOW) -> None:  # fmt: skip
        if rule not in RULES:
            raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
        if not 0.0 <= probe_below <= 1.0:
            raise ValueError(f"probe_below must lie in [0, 1], got {probe_below!r}")
        self.probe_below = float(probe_below)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.kernel = BeliefKernel(belief) if isinstance(belief, AmortisedBelief) else belief
        self.params = NeuronParams() if params is None else params
        self.rule, self.seed = rule, int(seed)
        self.rng = np.random.default_rng(self.seed)
        self.tracker: BeliefFeatureTracker | None = None
        self.probabilities = np.zeros((0, 3))  # [n, 3] the belief this step

    def spawn(self, index: int) -> AmortisedController:
        """A copy for sub-environment ``index`` of a vector environment (its own seed, and
        its own belief state: the weights are shared, the GRU's memory is not)."""
        return AmortisedController(copy.copy(self.kernel), self.params, self.rule,
                                   self.seed + index, self.probe_below)  # fmt: skip

    def reset(self) -> None:
        """Forget the episode (``act`` at step 0 also does)."""
        self.tracker = None

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The action for this observation (an agent index, -1 for do nothing)."""
        check_controller_input(observation, info, "AmortisedController",
                               ("voltage", "pattern", "target", "step"))  # fmt: skip
        if "voltage" not in observation:
            raise ControllerInputError(
                "AmortisedController.act: the belief reads the observed potentials, which "
                "spikes-only sensing does not give"
            )
        step = int(observation["step"])
        voltage = np.asarray(observation["voltage"])
        pattern = np.asarray(observation["pattern"])
        mask = np.asarray(info["action_mask"], dtype=bool)
        n, target = voltage.shape[0], int(observation["target"])
        if mask.shape != (n + 1,) or not 0 <= target < n:
            raise ControllerInputError(f"AmortisedController.act: action_mask must be [{n + 1}] "
                                       f"and the target in 0..{n - 1}")  # fmt: skip
        if step == 0 or self.tracker is None:
            if step != 0:
                raise ValueError("AmortisedController must see the episode from its first step")
            self.tracker = BeliefFeatureTracker(n, target, self.params)
            self.kernel.reset(target_prior(n, target))
            prior = target_prior(n, target)  # the generator's P(i -> target), 0 for the target
            self.probabilities = np.stack([1.0 - prior, prior * EXCITATORY_PROBABILITY,
                                           prior * (1.0 - EXCITATORY_PROBABILITY)], axis=1)
        else:
            row = self.tracker.row(voltage, int(observation.get("last_action", DO_NOTHING)))
            logits = self.kernel.step(row).astype(np.float64)  # [n, 3]
            logits -= logits.max(axis=1, keepdims=True)
            probabilities = np.exp(logits)
            self.probabilities = probabilities / probabilities.sum(axis=1, keepdims=True)
            self.probabilities[target] = (1.0, 0.0, 0.0)
        return self.decide(pattern, step, mask)

    @property
    def excitatory(self) -> np.ndarray:
        """[n] the belief's P(G[i, target] = +1) this step (0 for the target)."""
        return self.probabilities[:, 1]

    def decide(self, pattern: np.ndarray, step: int, mask: np.ndarray) -> int:
        """The action on the belief as it stands; a subclass replaces the rule here."""
        return self.rule_action(pattern, step, self.can_land(mask[1:]))

    def rule_action(self, pattern: np.ndarray, step: int, can_land: np.ndarray) -> int:
        """:func:`choose_action` on the belief, ``can_land`` [n] being :meth:`can_land`'s."""
        ahead = pattern[step + 1 : step + 1 + self.params.min_release_interval_steps]
        return choose_action(self.excitatory, can_land, ahead.astype(bool), self.rule,
                             self.rng, self.probe_below)  # fmt: skip

    def can_land(self, legal: np.ndarray) -> np.ndarray:
        """[n] bool: stimulated now, the neuron spikes and releases onto its targets at
        the next step (legal, not refractory, at least the release interval since its
        last release, and driven over threshold from its potential after the leak)."""
        tracker, p = self.tracker, self.params
        rested = tracker.since + 1 >= p.min_release_interval_steps
        potential = (tracker.after_reset - (tracker.after_reset - p.v_rest_mV) * p.leak_per_step
                     + p.stimulus_step_mV)  # fmt: skip
        return legal & rested & (tracker.refractory_left == 0) & (potential >= p.v_spike_mV)
