"""What identify-and-plan would do now: its next action as per-neuron inputs of a policy.

The guided learner imitates identify-and-plan and stops just below it; the planner
decides by a look-ahead on the network it has identified, which a student that sees
only potentials (or even the planner's belief, :mod:`spikectl.planning.belief`) does
not reproduce. :class:`PlannerAdvice` plays the planner itself beside a policy, as a
shadow: every episode of a batch has its own :class:`~spikectl.planning.policy.IdentifyAndPlan`
with the composition the named ``identify-and-plan`` plays the environment with
(:func:`~spikectl.planning.named.named_composition`), which observes the episode the
policy plays (the policy's actions, not its own) and says, at each step, which action it
would take. For every observed neuron i:

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

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING
from spikectl.planning.named import named_composition
from spikectl.planning.policy import IdentifyAndPlan

ADVICE_FEATURES = ("advised", "waits")
"""The per-neuron features of :class:`PlannerAdvice`, in order."""


class PlannerAdvice:
    """The advice features [S, n, 2] of a batch of S episodes, one step at a time.

    Call it on every observation batch of the episodes with the batch's action masks,
    from step 0 on; a row at step 0 starts a new planner, so an episode's advice is a
    function of its own observations alone (the planner's draws, where its settings make
    any, start from the same seed every episode). ``reset()`` forgets every episode. An
    observation at or past the pattern's end (an episode's last one, which no policy
    acts on) gets zeros. ``extensions``: the environment's (its measurement noise and the
    settings the planner plays it with); None: the paper's task.
    """

    def __init__(self, params: NeuronParams, extensions: Extensions | None = None) -> None:
        if not isinstance(params, NeuronParams):
            raise TypeError(f"params must be a NeuronParams, got {type(params).__name__}")
        if extensions is not None and not isinstance(extensions, Extensions):
            raise TypeError(f"extensions must be an Extensions, got {type(extensions).__name__}")
        self.params, self.extensions = params, extensions
        self.noise_mV = 0.0 if extensions is None else extensions.observation_noise_mV
        self.reset()

    def reset(self) -> None:
        """Forget every episode."""
        self._planners: list[IdentifyAndPlan | None] = []

    def _new_planner(self, n: int) -> IdentifyAndPlan:
        """The named identify-and-plan on this environment, with ``n`` observed neurons."""
        composition = named_composition(self.extensions, n)
        return IdentifyAndPlan(self.params, composition, extensions=self.extensions)

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
            self._planners = [None] * size
        features = np.zeros((size, n, len(ADVICE_FEATURES)), dtype=np.float32)
        for row in range(size):
            if steps[row] >= patterns.shape[-1]:
                continue  # the episode has ended: nothing to advise
            if steps[row] == 0:
                self._planners[row] = self._new_planner(n)
            elif self._planners[row] is None:
                raise ValueError("PlannerAdvice must see each episode from its first step")
            observation = {key: np.asarray(value)[row] for key, value in observations.items()}
            action = self._planners[row].act(observation, {"action_mask": mask[row]})
            if action == DO_NOTHING:
                features[row, :, 1] = 1.0
            else:
                features[row, action, 0] = 1.0
        return features
