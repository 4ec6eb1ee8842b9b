"""What the observations so far say about the target's inputs: a belief a policy can read.

identify-and-plan identifies the network by regression (:mod:`spikectl.planning.identify`)
and plans on what it has identified; a learned policy that sees only potentials has to
learn that identification itself, and at 32 neurons the guided learner does not
(docs/results/student-n32-diagnosis/). :class:`TargetInputBelief` runs the planner's own
identification (:class:`~spikectl.planning.identify.ObservedState` and
:class:`~spikectl.planning.identify.ConnectivityEstimate`, nothing copied) beside a
policy and gives, for every observed neuron i, three numbers about its synapse onto the
target under the Gaussian posterior N(m_i, s_i²) of G[i, target] in units of w_in:

- ``excites``      P(G[i, target] > 1/2): i is an excitatory input of the target;
- ``inhibits``     P(G[i, target] < -1/2): an inhibitory one;
- ``uncertainty``  s_i / prior sd of the entry: 1 while nothing was learnt, near 0 once known.

They are functions of the observations and actions alone (the hidden weights are never
read), so a policy that takes them as inputs is as realisable as the planner. The
estimate is the planner's Gaussian one under the paper's deterministic release, with
spikes read ``spike_margin_sd`` noise sds below threshold and the residual noise of the
measurement noise (:func:`~spikectl.planning.identify.residual_sd`); under the realism
variants it degrades as the planner's does. Every row of a batch is its own estimate,
so a row's features do not depend on the batch it is in.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from spikectl.neuron.params import NeuronParams
from spikectl.planning.identify import (
    ConnectivityEstimate,
    ObservedState,
    residual_sd,
    synapse_probabilities,
)

BELIEF_FEATURES = ("excites", "inhibits", "uncertainty")
"""The per-neuron features of :class:`TargetInputBelief`, in order."""


class TargetInputBelief:
    """The belief features [S, n, 3] of a batch of S episodes, one step at a time.

    Call it on every observation batch of the episodes, from step 0 on (a row at step 0
    starts a new estimate); ``reset()`` forgets every episode.
    """

    def __init__(
        self, params: NeuronParams, noise_mV: float = 0.0, spike_margin_sd: float = 2.0
    ) -> None:
        if not noise_mV >= 0:
            raise ValueError(f"noise_mV must be >= 0, got {noise_mV!r}")
        self.params = params
        self.noise_mV = float(noise_mV)
        self._spike_margin_mV = float(spike_margin_sd) * self.noise_mV
        self._residual_sd = residual_sd(params, self.noise_mV)
        self.reset()

    def reset(self) -> None:
        """Forget every episode."""
        self._rows: list[tuple[ObservedState, ConnectivityEstimate] | None] = []

    def __call__(
        self, observations: Mapping[str, np.ndarray], action_mask: np.ndarray | None = None
    ) -> np.ndarray:
        """float32 [S, n, 3]: the features after this step's observation (``voltage``
        [S, n], ``step``, ``last_action`` and ``target`` [S]); ``action_mask`` is not read
        (the signature of every belief input, :class:`BeliefInputs`)."""
        voltage = np.asarray(observations["voltage"], dtype=np.float64)  # [S, n]
        steps = np.asarray(observations["step"]).reshape(-1)  # [S]
        actions = np.asarray(observations["last_action"]).reshape(-1)  # [S]
        targets = np.asarray(observations["target"]).reshape(-1)  # [S]
        if voltage.ndim != 2:
            raise ValueError(f"voltage must be [S, n], got shape {voltage.shape}")
        size, n = voltage.shape
        if len(self._rows) != size:
            self._rows = [None] * size
        features = np.empty((size, n, len(BELIEF_FEATURES)), dtype=np.float32)
        for row in range(size):
            features[row] = self._step(row, voltage[row], int(steps[row]),
                                       int(actions[row]), int(targets[row]))  # fmt: skip
        return features

    def _step(self, row: int, voltage: np.ndarray, step: int, action: int, target: int):
        """[n, 3]: one row's features after its observation at ``step``."""
        n = voltage.shape[0]
        if step == 0:
            self._rows[row] = (
                ObservedState(n, self.params, self._spike_margin_mV),
                ConnectivityEstimate(n, self._residual_sd),
            )
        elif self._rows[row] is None:
            raise ValueError("TargetInputBelief must see each episode from its first step")
        tracker, estimate = self._rows[row]
        if step > 0:
            estimate.add(*tracker.observe(voltage, action))
        mean, sd = estimate.column(target)  # [n] each
        excites, inhibits = synapse_probabilities(mean, sd)  # [n] each
        uncertainty = sd / np.sqrt(estimate.prior_variance[:, target])
        return np.stack([excites, inhibits, np.minimum(uncertainty, 1.0)], axis=-1)


class BeliefInputs:
    """Several per-neuron inputs side by side: ``parts`` each map (observations [S, ...],
    action_mask [S, n + 1]) to float32 [S, n, W_k] and reset with ``reset()``
    (:class:`TargetInputBelief`, :class:`~spikectl.planning.advice.PlannerAdvice`);
    this gives [S, n, sum W_k], in the order of ``parts``."""

    def __init__(self, parts) -> None:
        self.parts = tuple(parts)
        if not self.parts:
            raise ValueError("BeliefInputs needs at least one part")

    def reset(self) -> None:
        """Forget every episode, in every part."""
        for part in self.parts:
            part.reset()

    def __call__(
        self, observations: Mapping[str, np.ndarray], action_mask: np.ndarray
    ) -> np.ndarray:
        """float32 [S, n, W]: every part's features at this step, concatenated."""
        return np.concatenate([part(observations, action_mask) for part in self.parts], axis=-1)


def episode_beliefs(
    belief,
    voltage: np.ndarray,
    actions: np.ndarray,
    targets: np.ndarray,
    patterns: np.ndarray,
    action_masks: np.ndarray,
) -> np.ndarray:
    """float32 [E, N + 1, n, W]: the features ``belief`` (a :class:`TargetInputBelief`,
    :class:`BeliefInputs`, ...) gives at every observation of E whole episodes
    (``voltage`` [E, N + 1, n], ``actions`` [E, N], ``targets`` [E], ``patterns`` [E, N],
    ``action_masks`` [E, n + 1]), the same numbers it gives when called step by step as
    they are played."""
    count, length, n = voltage.shape
    action_masks = np.asarray(action_masks, dtype=bool)
    belief.reset()
    steps = []
    for step in range(length):
        steps.append(belief({
            "voltage": voltage[:, step],
            "pattern": patterns,
            "step": np.full(count, step),
            "last_action": actions[:, step - 1] if step else np.full(count, -1),
            "target": targets,
        }, action_masks))  # fmt: skip
    belief.reset()
    return np.stack(steps, axis=1).astype(np.float32, copy=False)  # [E, N + 1, n, W]
