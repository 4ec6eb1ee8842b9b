"""What identify-and-plan would do now: its next action as per-neuron inputs of a policy.

The guided learner imitates identify-and-plan and stops just below it; the planner
decides by a look-ahead on the network it has identified, which a student that sees
only potentials (or even the planner's belief, :mod:`spikectl.planning.belief`) does
not reproduce. :class:`PlannerAdvice` plays the planner itself beside a policy, as a
shadow: every row of a batch has its own :class:`~spikectl.planning.policy.IdentifyAndPlan`,
which observes the episode the policy plays (the policy's actions, not its own) and
says, at each step, which action it would take. For every observed neuron i:

- ``advised``  1 where the planner would stimulate i now, else 0;
- ``waits``    1 on every neuron where the planner would do nothing now, else 0.

A learned policy that reads them can follow the planner where it is right and, trained
on reward, leave it where it is wrong (residual or advised RL). They are functions of
the observations and actions alone, as the planner's decisions are, so such a policy is
as realisable as the planner; it costs the planner's CPU time at every step.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from spikectl.neuron.params import NeuronParams
from spikectl.planning.policy import IdentifyAndPlan

ADVICE_FEATURES = ("advised", "waits")
"""The per-neuron features of :class:`PlannerAdvice`, in order."""

DO_NOTHING = -1


class PlannerAdvice:
    """The advice features [S, n, 2] of a batch of S episodes, one step at a time.

    Call it on every observation batch of the episodes with the batch's action masks,
    from step 0 on (a row at step 0 starts a new planner); ``reset()`` forgets every
    episode. An observation at or past the pattern's end (an episode's last one, which
    no policy acts on) gets zeros. ``width``: the planner's beam width (the guided
    learner's teacher uses 32, the planner's default).
    """

    def __init__(self, params: NeuronParams, noise_mV: float = 0.0, width: int = 32) -> None:
        if not noise_mV >= 0:
            raise ValueError(f"noise_mV must be >= 0, got {noise_mV!r}")
        self.params, self.noise_mV, self.width = params, float(noise_mV), int(width)
        self.reset()

    def reset(self) -> None:
        """Forget every episode."""
        self._planners: list[IdentifyAndPlan] = []

    def __call__(
        self, observations: Mapping[str, np.ndarray], action_mask: np.ndarray
    ) -> np.ndarray:
        """float32 [S, n, 2]: the features at this step's observation (``voltage`` [S, n],
        ``pattern`` [S, N], ``step``, ``last_action`` and ``target`` [S]); ``action_mask``
        bool [S, n + 1]."""
        voltage = np.asarray(observations["voltage"])  # [S, n]
        steps = np.asarray(observations["step"]).reshape(-1)  # [S]
        patterns = np.asarray(observations["pattern"])  # [S, N]
        mask = np.asarray(action_mask, dtype=bool)  # [S, n + 1]
        if voltage.ndim != 2:
            raise ValueError(f"voltage must be [S, n], got shape {voltage.shape}")
        size, n = voltage.shape
        if mask.shape != (size, n + 1):
            raise ValueError(f"action_mask must have shape {[size, n + 1]}, got {list(mask.shape)}")
        if len(self._planners) != size:
            self._planners = [
                IdentifyAndPlan(self.params, width=self.width, noise_mV=self.noise_mV)
                for _ in range(size)
            ]
        features = np.zeros((size, n, len(ADVICE_FEATURES)), dtype=np.float32)
        for row in range(size):
            if steps[row] >= patterns.shape[-1]:
                continue  # the episode has ended: nothing to advise
            observation = {key: np.asarray(value)[row] for key, value in observations.items()}
            action = self._planners[row].act(observation, {"action_mask": mask[row]})
            if action == DO_NOTHING:
                features[row, :, 1] = 1.0
            else:
                features[row, action, 0] = 1.0
        return features
