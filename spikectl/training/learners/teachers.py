"""Teachers' labels for the agent's own episodes (DAgger-style relabelling).

A teacher is a controller that reads only the observation and the legal actions
(``IdentifyAndPlan``'s interface), or the oracle planner, which reads nothing of the
episode but its step and replays its plan of the played network. Played *beside* a
finished episode it sees every observation the agent saw, including the action the agent
actually took (the observation's ``last_action``), and says what it would have done at
each step: the label. Labelling after the episode is exact because the controller's choice depends
on nothing but those observations (and, for the privileged teacher, the weights).
Under spikes-only sensing the teacher sees what the environment showed, the spikes (the
agent reads them as potentials at threshold: ``envs.sensing``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from spikectl.contexts import Context, ContextSet
from spikectl.envs.controller import Controller, first_decision_refusal
from spikectl.envs.env import NeuronControlEnv
from spikectl.envs.rollout import EpisodeBatch
from spikectl.envs.sensing import as_sensed, make_observation
from spikectl.neuron.extensions import Extensions
from spikectl.neuron.params import NeuronParams
from spikectl.planning import Composition, IdentifyAndPlan
from spikectl.planning.lit_search import planned_light
from spikectl.planning.oracle import OraclePlanner


def make_teacher(
    teacher: str,
    context: Context,
    params: NeuronParams,
    extensions: Extensions | None,
    width: int,
    composition: Composition | None = None,
) -> Controller:
    """A fresh teacher for one episode on ``context`` in an environment with
    ``extensions``: identify-and-plan (``"identify"``, playing ``composition``, e.g. the
    environment's :func:`~spikectl.planning.named.named_composition` with ``fast=True``;
    None: the paper's), the paper's composition told the context's weights
    (``"told-weights"``) or the oracle planner of the context alone (``"oracle"``; its
    ``info["context_index"]`` is 0), each planning at beam ``width``."""
    if teacher == "identify":
        return IdentifyAndPlan(params, (composition or Composition()).with_width(width),
                               extensions=extensions)  # fmt: skip
    if teacher == "told-weights":
        if context.n_observed != context.n_neurons:
            raise ValueError(
                "teacher 'told-weights' needs every neuron observed; this environment "
                "hides some (use teacher 'identify')"
            )
        return IdentifyAndPlan(params, Composition().with_width(width), extensions=extensions,
                               told_weights=context.weights)  # fmt: skip
    if teacher == "oracle":  # it reads the latency from the observation's actions in flight
        return make_oracle_teacher([context], params, extensions, width)
    raise ValueError(f"unknown teacher {teacher!r}: 'identify', 'told-weights' or 'oracle'")


def make_oracle_teacher(
    contexts: Sequence[Context], params: NeuronParams, extensions: Extensions | None, width: int
) -> OraclePlanner:
    """The oracle teacher of ``contexts``: the oracle planner at beam ``width``, planning
    for the environment's actuator (each context's plan is made once and kept)."""
    target_action = extensions is not None and extensions.allow_target_action
    return OraclePlanner(contexts, params, width, target_action,
                         light_mW_per_mm2=planned_light(extensions))  # fmt: skip


def oracle_labels(
    oracle: OraclePlanner, indices: Sequence[int], extensions: Extensions | None
) -> np.ndarray:
    """[S, N] int16: the oracle teacher's plan of each of its contexts ``indices[s]``, in
    the agent's indexing, for the environment's loop latency: the label of step t is the
    action it chooses at t (which lands at t + L), whatever the episode did."""
    latency = 0 if extensions is None else extensions.latency_steps
    return np.stack([oracle.plan(int(i), latency) for i in indices]).astype(np.int16)


class TeacherMixedPolicy:
    """A round's collection policy where the teacher plays some episodes itself (DAgger's
    mixture of the teacher and the student, drawn per episode): ``teacher_plays[s]``
    says whether sub-environment s's episode is the teacher's. The student's policy
    still steps on every observation (its draws and recurrent state stay those of a
    round without a teacher); the teacher's actions replace its own where it plays."""

    def __init__(self, student, teacher_plays: np.ndarray, make: Callable[[], Controller]):
        self.student, self.teacher_plays = student, teacher_plays
        self.teachers = {int(s): make() for s in np.flatnonzero(teacher_plays)}
        self.teacher_seconds = 0.0
        """CPU seconds the teacher spent choosing (part of the learner's)."""

    def __call__(self, observations: dict[str, np.ndarray], action_mask: np.ndarray) -> np.ndarray:
        actions = self.student(observations, action_mask)  # [S]
        started = time.process_time()
        observations = as_sensed(observations)  # what the environment showed
        for s, teacher in self.teachers.items():
            observation = {key: value[s] for key, value in observations.items()}
            actions[s] = teacher.act(observation, {"action_mask": action_mask[s]})
        self.teacher_seconds += time.process_time() - started
        return actions


def teacher_labels(
    episodes: EpisodeBatch,
    contexts: Sequence[Context],
    teacher: str,
    params: NeuronParams,
    extensions: Extensions | None = None,
    width: int = 32,
    played: np.ndarray | None = None,
    composition: Composition | None = None,
) -> np.ndarray:
    """[S, N] int16: the teacher's action at every step of each of the S episodes
    (episode s played ``contexts[s]``), in the agent's indexing (-1 = do nothing);
    ``extensions`` and ``composition`` as :func:`make_teacher`'s.
    Episodes the teacher played itself (``played[s]``) are labelled with their actions
    (what it would do again), without playing it a second time."""
    count, length = episodes.actions.shape
    if len(contexts) != count:
        raise ValueError(f"{count} episodes but {len(contexts)} contexts")
    if teacher == "oracle":  # open loop: its labels do not depend on the episode
        oracle = make_oracle_teacher(contexts, params, extensions, width)
        return oracle_labels(oracle, range(count), extensions)
    labels = np.empty((count, length), dtype=np.int16)
    for s, context in enumerate(contexts):
        if played is not None and played[s]:
            labels[s] = episodes.actions[s]
            continue
        policy = make_teacher(teacher, context, params, extensions, width, composition)
        info = {"action_mask": episodes.action_mask[s], "context_index": 0}
        pattern = np.asarray(context.pattern, dtype=np.int8)
        target = context.observed_target
        # With loop latency L, observation t carries the actions chosen at t - L .. t - 1.
        latency = 0 if extensions is None else extensions.latency_steps
        chosen = np.concatenate([np.full(latency, -1, np.int64), episodes.actions[s]])
        # Spikes-only sensing shows the spikes of the step just simulated (none at 0).
        spikes_only = extensions is not None and extensions.spikes_only
        if spikes_only:
            shown = np.concatenate([np.zeros_like(episodes.spikes[s, :1]), episodes.spikes[s]])
        for t in range(length):
            observation = make_observation(
                shown[t].astype(np.int8) if spikes_only else episodes.voltage[s, t],
                spikes_only, target, pattern, t,
                -1 if t == 0 else int(episodes.actions[s, t - 1]),
                chosen[t : t + latency] if latency else None,
            )  # fmt: skip
            labels[s, t] = policy.act(observation, info)
    return labels


def teacher_refusal(
    env, teacher: str, width: int, composition: Composition | None = None
) -> str | None:
    """Why ``teacher`` cannot play the environment of ``env`` (an ``EnvConfig``), or None
    where it can: the teacher is made as a run makes it, for one context of that
    environment (:func:`~spikectl.envs.controller.first_decision_refusal`)."""
    contexts = ContextSet.generate(1, env.n_neurons, env.episode_length, env.context_seed,
                                   env.params, env.extensions)  # fmt: skip
    played = NeuronControlEnv(contexts=contexts, extensions=env.extensions.environment_part())
    return first_decision_refusal(played, lambda: make_teacher(
        teacher, contexts[0], contexts.params, env.extensions, width, composition
    ))  # fmt: skip
