"""Beam search over action sequences with the batched simulator (the planner's core).

The planner never has its own copy of the dynamics: every candidate step is one call
of :func:`spikectl.neuron.simulator.advance` on a batch of simulator states, one per
(beam entry, action) pair. Two facts of the model (docs/model.md) make a beam search strong
here:

* an action at step t reaches the target no earlier than step t + 1 (the target is
  not stimulable and synaptic input takes one step), so the reward of step t + 1 is
  already *committed* once step t is simulated. The beam ranks candidates by their
  reward so far plus that committed reward, which sees one step past the decision;
* many action sequences lead to the same simulator state (stimulating a refractory
  neuron does nothing; release counters saturate), so duplicates are merged and the
  beam's width is spent on distinct states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.envs.env_support import step_rewards
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.prediction import one_step
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance

# Voltages are compared at this resolution (mV) when duplicate states are merged: far
# below any difference the dynamics can act on, far above float round-off.
_VOLTAGE_RESOLUTION_MV = 1e-7
# Weight of the target's depolarisation (mV) in the ranking: 20 mV of it is worth far
# less than the smallest reward (0.5 / 59 per step), so it only breaks ties.
_TIE_BREAK = 1e-6
# Seed of the fixed projections that hash simulator states for merging duplicates.
_PROJECTION_SEED = 20261122


@dataclass(frozen=True)
class PlanningModel:
    """What the planner simulates: one network, its target and the legal actions.

    Attributes:
        weights: [K, n, n] int8 signs or float64 signed synaptic strengths in units of
            w_in (what :func:`spikectl.neuron.simulator.advance` takes): K = 1 for a known
            network, K > 1 for hypotheses about an uncertain one (planned on at once,
            ranked by the mean return over them).
        target: the neuron whose spikes are rewarded (a neuron index of the model).
        actions: int64 [A] the legal simulator actions, do nothing (-1) first.
        params: the neuron parameters.
        neurons: per-neuron kernel parameters [1, 2, n] (heterogeneous neurons), or None.
    """

    weights: np.ndarray
    target: int
    actions: np.ndarray
    params: NeuronParams
    neurons: np.ndarray | None = None

    @property
    def n_neurons(self) -> int:
        return self.weights.shape[-1]

    @property
    def hypotheses(self) -> int:
        """K, the number of networks planned on at once (1: a known network)."""
        return self.weights.shape[0]


@dataclass(frozen=True)
class Plan:
    """The best action sequence found from a start state."""

    actions: np.ndarray
    """int64 [H] simulator actions for steps start .. start + H - 1."""
    rewards: np.ndarray
    """float64 [H] the rewards the model predicts for them."""

    @property
    def predicted_return(self) -> float:
        return float(self.rewards.sum())


def _committed_target_spike(model: PlanningModel, state: SimulatorState) -> np.ndarray:
    """[K * E] whether the target spikes at the next step whatever the next action is
    (it is not stimulable; rows hypothesis-major, as in the beam)."""
    k = model.hypotheses
    size = state.voltage_mV.shape[0] // k
    committed = np.empty(k * size, dtype=bool)
    for h in range(k):
        block = slice(h * size, (h + 1) * size)
        _, committed[block] = one_step(_block(state, block), model.weights[h : h + 1],
                                       DO_NOTHING, model.params, model.neurons,
                                       neuron=model.target)  # fmt: skip
    return committed


def state_signature_rows(
    state: SimulatorState, release_interval: int, hypotheses: int, entries: int
) -> np.ndarray:
    """[entries, K * 4n] float64 rows, equal exactly for beam entries the dynamics
    cannot tell apart (under every hypothesis; state rows are hypothesis-major)."""
    parts = np.concatenate(
        [
            np.round(state.voltage_mV / _VOLTAGE_RESOLUTION_MV),
            state.refractory_left,
            np.minimum(state.steps_since_release, release_interval),
            state.released,
        ],
        axis=1,
    )  # [K * E, 4n]
    parts = parts.reshape(hypotheses, entries, -1).transpose(1, 0, 2).reshape(entries, -1)
    return np.ascontiguousarray(parts, dtype=np.float64)  # [E, K * 4n]


def _first_of_each(rows: np.ndarray) -> np.ndarray:
    """Indices of the first occurrence of each distinct row of ``rows`` [E, D], sorted.

    Rows are compared through a fixed random projection (fast: np.unique on [E]
    numbers instead of E keys of 8 D bytes); every row is then checked against the
    representative it was merged with, and any collision falls back to comparing
    whole rows, so the result is exact.
    """
    projection = np.random.default_rng(_PROJECTION_SEED).standard_normal(rows.shape[1])
    hashed = rows @ projection  # [E]
    _, first, inverse = np.unique(hashed, return_index=True, return_inverse=True)
    if np.array_equal(rows, rows[first[inverse]]):
        return np.sort(first)
    keys = rows.view(np.dtype((np.void, rows.itemsize * rows.shape[1])))[:, 0]
    _, first = np.unique(keys, return_index=True)
    return np.sort(first)


def take_states(state: SimulatorState, rows: np.ndarray) -> SimulatorState:
    return SimulatorState(
        state.voltage_mV[rows], state.refractory_left[rows],
        state.steps_since_release[rows], state.released[rows],
    )  # fmt: skip


def _block(state: SimulatorState, rows: slice) -> SimulatorState:
    """A view of contiguous rows (the kernel advances it in place)."""
    return SimulatorState(
        state.voltage_mV[rows], state.refractory_left[rows],
        state.steps_since_release[rows], state.released[rows],
    )  # fmt: skip


def beam_search(
    model: PlanningModel,
    start: SimulatorState,
    pattern: np.ndarray,
    start_step: int = 0,
    width: int = 64,
    horizon: int | None = None,
) -> Plan:
    """Search action sequences from ``start`` (a batch of one state) for the best return.

    With K hypotheses (``model.weights`` [K, n, n], K > 1) one action sequence is
    played on all K networks at once and ranked by its mean return over them: the
    sequence that is best in expectation over what the weights might be.

    Args:
        model: the network (or the K hypothetical networks) to plan on.
        start: the simulator state before step ``start_step`` (batch size 1).
        pattern: [N] bool target pattern of the whole episode.
        start_step: the first step to plan.
        width: beam width (distinct states kept per step).
        horizon: steps to plan; None: to the end of the episode.

    Returns:
        The best :class:`Plan` (ties go to the earliest do-nothing-first sequence, so
        the result is deterministic); its rewards are means over the hypotheses.
    """
    if width < 1:
        raise ValueError(f"width must be >= 1, got {width}")
    pattern = np.asarray(pattern, dtype=bool)
    episode_length = pattern.shape[0]
    if not 0 <= start_step < episode_length:
        raise ValueError(f"start_step must lie in 0..{episode_length - 1}, got {start_step}")
    end = episode_length if horizon is None else min(episode_length, start_step + horizon)
    reward_if_spike, reward_if_silent = step_rewards(pattern)
    n, actions, k = model.n_neurons, model.actions, model.hypotheses
    n_actions = actions.shape[0]
    interval = min(model.params.min_release_interval_steps, 2**30)
    resting = model.params.v_rest_mV
    # States are stored hypothesis-major: row h * size + e is beam entry e under
    # hypothesis h, so each hypothesis is one contiguous block for the kernel.
    beam = take_states(start, np.zeros(k, dtype=np.int64))  # [K * 1, n]
    score = np.zeros(1)
    parents, choices, step_rewards_kept = [], [], []
    for t in range(start_step, end):
        size = score.shape[0]
        n_children = size * n_actions
        rows = np.repeat(np.arange(size), n_actions)  # [size * A]
        state_rows = (np.arange(k)[:, None] * size + rows[None, :]).ravel()  # [K * size * A]
        children = take_states(beam, state_rows)
        child_actions = np.tile(actions, size)  # [size * A]
        voltage = np.empty((k * n_children, 1, n))
        spikes = np.empty((k * n_children, 1, n), dtype=bool)
        step_actions = np.ascontiguousarray(child_actions[:, None])  # [size * A, 1]
        for h in range(k):
            block = slice(h * n_children, (h + 1) * n_children)
            advance(_block(children, block), model.weights[h : h + 1], step_actions,
                    model.params, voltage[block], spikes[block], model.neurons)  # fmt: skip
        spiked = spikes[:, 0, model.target].reshape(k, n_children)  # [K, size * A]
        reward = np.where(spiked, reward_if_spike[t], reward_if_silent[t]).mean(axis=0)
        child_score = score[rows] + reward
        ranking = child_score.copy()
        if t + 1 < end:
            committed = _committed_target_spike(model, children).reshape(k, n_children)
            ranking += np.where(committed, reward_if_spike[t + 1],
                                reward_if_silent[t + 1]).mean(axis=0)  # fmt: skip
        # Ties (common: most steps reward silence whatever is done) go to the state
        # whose target sits highest: an inhibited target needs more input later.
        depolarisation = np.clip(children.voltage_mV[:, model.target] - resting, -20.0, 20.0)
        ranking += _TIE_BREAK * depolarisation.reshape(k, n_children).mean(axis=0)
        order = np.argsort(-ranking, kind="stable")
        rows_ordered = state_signature_rows(children, interval, k, n_children)[order]  # [C, K * 4n]
        kept = order[_first_of_each(rows_ordered)][:width]
        beam = take_states(children, (np.arange(k)[:, None] * n_children + kept[None, :]).ravel())
        score = child_score[kept]
        parents.append(rows[kept])
        choices.append(child_actions[kept])
        step_rewards_kept.append(reward[kept])
    best = int(np.argmax(score))
    plan_actions = np.empty(end - start_step, dtype=np.int64)
    plan_rewards = np.empty(end - start_step)
    for step in range(end - start_step - 1, -1, -1):
        plan_actions[step] = choices[step][best]
        plan_rewards[step] = step_rewards_kept[step][best]
        best = int(parents[step][best])
    return Plan(plan_actions, plan_rewards)
