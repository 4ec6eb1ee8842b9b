"""Teachers' labels for the agent's own episodes (DAgger-style relabelling).

A teacher is a closed-loop controller that reads only the observation and the legal
actions (``IdentifyAndPlan``'s interface). Played *beside* a finished episode it sees
every observation the agent saw, including the action the agent actually took (the
observation's ``last_action``), and says what it would have done at each step: the
label. Labelling after the episode is exact because the controller's choice depends
on nothing but those observations (and, for the privileged teacher, the weights).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from spikectl.contexts import Context
from spikectl.envs.rollout import EpisodeBatch
from spikectl.neuron.params import NeuronParams
from spikectl.planning import IdentifyAndPlan


def make_teacher(
    teacher: str, context: Context, params: NeuronParams, noise_mV: float, width: int
) -> IdentifyAndPlan:
    """A fresh teacher for one episode on ``context``: identify-and-plan
    (``"identify"``) or the same loop told the context's weights (``"told-weights"``)."""
    if teacher == "identify":
        return IdentifyAndPlan(params, width=width, noise_mV=noise_mV)
    if teacher == "told-weights":
        if context.n_observed != context.n_neurons:
            raise ValueError(
                "teacher 'told-weights' needs every neuron observed; this environment "
                "hides some (use teacher 'identify')"
            )
        return IdentifyAndPlan(params, width=width, noise_mV=noise_mV,
                               known_weights=context.weights)  # fmt: skip
    raise ValueError(f"unknown teacher {teacher!r}: 'identify' or 'told-weights'")


def teacher_labels(
    episodes: EpisodeBatch,
    contexts: Sequence[Context],
    teacher: str,
    params: NeuronParams,
    noise_mV: float = 0.0,
    width: int = 32,
) -> np.ndarray:
    """[S, N] int16: the teacher's action at every step of each of the S episodes
    (episode s played ``contexts[s]``), in the agent's indexing (-1 = do nothing)."""
    count, length = episodes.actions.shape
    if len(contexts) != count:
        raise ValueError(f"{count} episodes but {len(contexts)} contexts")
    labels = np.empty((count, length), dtype=np.int16)
    for s, context in enumerate(contexts):
        policy = make_teacher(teacher, context, params, noise_mV, width)
        info = {"action_mask": episodes.action_mask[s]}
        pattern = np.asarray(context.pattern, dtype=np.int8)
        target = context.observed_target
        for t in range(length):
            observation = {
                "voltage": episodes.voltage[s, t],
                "target": target,
                "pattern": pattern,
                "step": t,
                "last_action": -1 if t == 0 else int(episodes.actions[s, t - 1]),
            }
            labels[s, t] = policy.act(observation, info)
    return labels
