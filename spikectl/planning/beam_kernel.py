"""The beam search of :func:`spikectl.planning.beam.beam_search`, compiled (Numba).

Kept apart from the planner's public types so that each module reads in one sitting: this
one is the loop over steps, hypotheses, beam entries and actions, and the exact state hash
that merges duplicate children (:func:`search`).
"""

from __future__ import annotations

import numba
import numpy as np

from spikectl.neuron.kernel import (
    LEAK_PER_STEP,
    V_REST_MV,
    V_SPIKE_MV,
    kernel_constants,
    predict_neuron,
    step_constants,
    step_network,
    step_neuron,
)
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState

# Voltages are compared at this resolution (mV) when duplicate states are merged: far
# below any difference the dynamics can act on, far above float round-off.
VOLTAGE_RESOLUTION_MV = 1e-7
# Weight of the target's depolarisation (mV) in the ranking: 20 mV of it is worth far
# less than the smallest reward (0.5 / 59 per step), so it only breaks ties.
_TIE_BREAK = 1e-6
# Seed of the fixed multipliers that hash simulator states for merging duplicates.
_HASH_SEED = 20261122


_MULTIPLIERS: dict[int, np.ndarray] = {}


def multipliers(size: int) -> np.ndarray:
    """int64 [size] the fixed random odd multipliers of the state hash (kept per size)."""
    if size not in _MULTIPLIERS:
        rng = np.random.default_rng(_HASH_SEED)
        _MULTIPLIERS[size] = rng.integers(0, 2**62, size, dtype=np.int64) * 2 + 1
    return _MULTIPLIERS[size]


def search(
    model, start: SimulatorState, rewards: tuple[np.ndarray, np.ndarray], start_step: int,
    end: int, width: int,
) -> tuple[np.ndarray, np.ndarray]:
    """(actions int64 [H], rewards [H]) of the best sequence over steps start_step ..
    end - 1 from ``start`` (a batch of one) on ``model`` (a
    :class:`~spikectl.planning.beam.PlanningModel`), keeping ``width`` distinct states a
    step; ``rewards`` = (reward if the target spikes, if it is silent) per step."""
    constants = kernel_constants(model.params)
    n = model.n_neurons
    if model.neurons is None:  # the paper's neurons: the same numbers for every neuron
        neurons = np.empty((2, n))
        neurons[0], neurons[1] = constants[V_SPIKE_MV], constants[LEAK_PER_STEP]
    elif model.neurons.shape == (1, 2, n):
        neurons = np.ascontiguousarray(model.neurons[0], dtype=np.float64)
    else:
        raise ValueError(f"model.neurons must have shape [1, 2, n], got {model.neurons.shape}")
    return _search(
        np.ascontiguousarray(model.weights), np.ascontiguousarray(model.actions, dtype=np.int64),
        int(model.target), constants, neurons,
        np.ascontiguousarray(start.voltage_mV[0]), np.ascontiguousarray(start.refractory_left[0]),
        np.ascontiguousarray(start.steps_since_release[0]), np.ascontiguousarray(start.released[0]),
        rewards[0], rewards[1], int(start_step), int(end), int(width),
        int(min(model.params.min_release_interval_steps, 2**30)),
        multipliers(model.n_neurons * model.hypotheses),
    )  # fmt: skip


def _search(
    weights, actions, target, constants, neurons, voltage, refractory_left,
    steps_since_release, released, reward_if_spike, reward_if_silent, start_step, end,
    width, interval, multipliers,
):  # fmt: skip
    """The compiled beam search; returns (actions [H], rewards [H]).

    Each step expands every beam entry by every action (child c = entry c // A, action
    c % A), plays it under each of the K hypotheses, ranks the children by (reward so
    far + the committed reward of the next step + the target's depolarisation as a tie
    break), each a mean over the hypotheses summed in hypothesis order as NumPy's
    ``mean(axis=0)`` sums, and keeps the first ``width`` distinct states in that order
    (a stable sort: ties go to the lower child index).

    A child is not stored whole: an action enters the step only through its own neuron
    (:func:`spikectl.neuron.kernel.step_neuron`), so each entry's do-nothing child is
    stepped in full and every other child is that state with the stimulated neuron
    stepped again; only the children kept become states of the beam.
    """
    k, n = weights.shape[0], weights.shape[2]
    n_actions = actions.shape[0]
    model = step_constants(constants)
    resting = constants[V_REST_MV]
    threshold, leak = neurons[0], neurons[1]
    most = width * n_actions
    # The beam's states, and the do-nothing child of each: [K, width, n].
    beam_v, none_v = np.empty((k, width, n)), np.empty((k, width, n))
    beam_r, none_r = np.empty((k, width, n), np.int32), np.empty((k, width, n), np.int32)
    beam_s, none_s = np.empty((k, width, n), np.int32), np.empty((k, width, n), np.int32)
    beam_x, none_x = np.empty((k, width, n), np.bool_), np.empty((k, width, n), np.bool_)
    # The stimulated neuron's state in each child: [K, children].
    act_v, act_r = np.empty((k, most)), np.empty((k, most), np.int32)
    act_s, act_x = np.empty((k, most), np.int32), np.empty((k, most), np.bool_)
    for h in range(k):
        beam_v[h, 0] = voltage
        beam_r[h, 0] = refractory_left
        beam_s[h, 0] = steps_since_release
        beam_x[h, 0] = released
    # Scratch: one network's state, stepped in place.
    v, r = np.empty(n), np.empty(n, np.int32)
    since, x = np.empty(n, np.int32), np.empty(n, np.bool_)
    synaptic_input = np.empty(n)
    out_v, out_s = np.empty((1, 1, n)), np.empty((1, 1, n), dtype=np.bool_)
    spiked = np.empty((k, most), dtype=np.bool_)
    committed = np.empty((k, most), dtype=np.bool_)
    depolarisation = np.empty((k, most))
    none_hash = np.empty(width, dtype=np.int64)
    # What duplicates are merged on (state_signature_rows): the do-nothing children's
    # [K, width, 4, n], and the stimulated neuron's [K, children, 4] (filled when scanned).
    none_key = np.empty((k, width, 4, n))
    act_key = np.empty((k, most, 4))
    reward = np.empty(most)
    child_score = np.empty(most)
    ranking = np.empty(most)
    score = np.zeros(width)
    horizon = end - start_step
    parents = np.empty((horizon, width), dtype=np.int64)
    choices = np.empty((horizon, width), dtype=np.int64)
    rewards_kept = np.empty((horizon, width))
    kept = np.empty(width, dtype=np.int64)
    kept_hash = np.empty(width, dtype=np.int64)
    idle = np.empty(most, dtype=np.bool_)
    candidates = np.empty(most, dtype=np.int64)
    nothing_first = n_actions > 0 and actions[0] == DO_NOTHING
    size = 1
    for t in range(start_step, end):
        n_children = size * n_actions
        look_ahead = t + 1 < end
        none_hash[:size] = 0
        # A child whose action changed nothing (a refractory neuron stimulated) is its
        # do-nothing sibling again, with the same rank and a higher index: never kept.
        idle[:n_children] = nothing_first
        for h in range(k):
            w = weights[h]
            for e in range(size):
                # The do-nothing child: the whole step. It leaves the entry's synaptic
                # input in synaptic_input, the same whatever the action.
                for j in range(n):
                    v[j] = beam_v[h, e, j]
                    r[j] = beam_r[h, e, j]
                    since[j] = beam_s[h, e, j]
                    x[j] = beam_x[h, e, j]
                step_network(w, DO_NOTHING, v, r, since, x, synaptic_input, model, out_v,
                             out_s, 0, 0, threshold, leak, None, None)  # fmt: skip
                for j in range(n):
                    none_v[h, e, j] = v[j]
                    none_r[h, e, j] = r[j]
                    none_s[h, e, j] = since[j]
                    none_x[h, e, j] = x[j]
                    _signature(v[j], r[j], since[j], x[j], interval, none_key[h, e, :, j])
                    term = _term(h * n + j, none_key[h, e, :, j], multipliers)
                    none_hash[e] = (none_hash[e] + term) & _HASH_MASK
                none_spiked = out_s[0, 0, target]
                none_depolarisation = min(max(v[target] - resting, -20.0), 20.0)
                # The target spikes at the next step whatever the next action is (it is
                # not stimulable): that reward is already committed.
                none_committed = False
                if look_ahead:
                    none_committed = predict_neuron(w, DO_NOTHING, v, r, x, model, target,
                                                    threshold, leak)[1]  # fmt: skip
                for i in range(n_actions):
                    c = e * n_actions + i
                    a = actions[i]
                    spiked[h, c] = none_spiked
                    depolarisation[h, c] = none_depolarisation
                    committed[h, c] = none_committed
                    if a == DO_NOTHING:
                        continue
                    # An action enters the step only through its own neuron: the child
                    # is the do-nothing child with neuron a stepped again, stimulated.
                    v_a, r_a, since_a, x_a, _, spiked_a = step_neuron(
                        a, beam_v[h, e, a], beam_r[h, e, a], beam_s[h, e, a],
                        synaptic_input[a], a, model, threshold[a], leak[a], False, False, None,
                    )  # fmt: skip
                    act_v[h, c], act_r[h, c], act_s[h, c], act_x[h, c] = v_a, r_a, since_a, x_a
                    if a == target or (v_a, r_a, since_a, x_a) != (v[a], r[a], since[a], x[a]):
                        idle[c] = False
                    if a == target:
                        spiked[h, c] = spiked_a
                        depolarisation[h, c] = min(max(v_a - resting, -20.0), 20.0)
                    # A new release changes the target's next input only through a
                    # synapse onto it; without one the sum adds an exact 0 and the
                    # do-nothing sibling's prediction stands, bit for bit.
                    if look_ahead and (a == target or (x_a != x[a] and w[a, target] != 0)):
                        kept_a = v[a], r[a], since[a], x[a]
                        v[a], r[a], since[a], x[a] = v_a, r_a, since_a, x_a
                        committed[h, c] = predict_neuron(w, DO_NOTHING, v, r, x, model, target,
                                                         threshold, leak)[1]  # fmt: skip
                        v[a], r[a], since[a], x[a] = kept_a
        count = 0
        for c in range(n_children):
            if idle[c] and actions[c % n_actions] != DO_NOTHING:
                continue
            candidates[count] = c
            count += 1
            total = 0.0
            for h in range(k):
                total += reward_if_spike[t] if spiked[h, c] else reward_if_silent[t]
            reward[c] = total / k
            child_score[c] = score[c // n_actions] + reward[c]
            ranking[c] = child_score[c]
            if look_ahead:
                total = 0.0
                for h in range(k):
                    total += reward_if_spike[t + 1] if committed[h, c] else reward_if_silent[t + 1]
                ranking[c] += total / k
            # Ties (common: most steps reward silence whatever is done) go to the state
            # whose target sits highest: an inhibited target needs more input later.
            total = 0.0
            for h in range(k):
                total += depolarisation[h, c]
            ranking[c] += _TIE_BREAK * (total / k)
        # The first `width` distinct states in ranking order (duplicates merged).
        order = np.argsort(-ranking[candidates[:count]], kind="mergesort")
        found = 0
        for index in order:
            c = candidates[index]
            e, a = c // n_actions, actions[c % n_actions]
            signature = none_hash[e]
            if a != DO_NOTHING:
                for h in range(k):
                    _signature(act_v[h, c], act_r[h, c], act_s[h, c], act_x[h, c], interval,
                               act_key[h, c])  # fmt: skip
                    signature += _term(h * n + a, act_key[h, c], multipliers)
                    signature -= _term(h * n + a, none_key[h, e, :, a], multipliers)
                    signature &= _HASH_MASK
            duplicate = False
            for i in range(found):
                if kept_hash[i] == signature and _same_child(
                    c, kept[i], actions, none_key, act_key
                ):
                    duplicate = True
                    break
            if not duplicate:
                kept[found] = c
                kept_hash[found] = signature
                found += 1
                if found == width:
                    break
        step = t - start_step
        for i in range(found):
            c = kept[i]
            e, a = c // n_actions, actions[c % n_actions]
            for h in range(k):
                for j in range(n):
                    beam_v[h, i, j] = none_v[h, e, j]
                    beam_r[h, i, j] = none_r[h, e, j]
                    beam_s[h, i, j] = none_s[h, e, j]
                    beam_x[h, i, j] = none_x[h, e, j]
                if a != DO_NOTHING:
                    beam_v[h, i, a], beam_r[h, i, a] = act_v[h, c], act_r[h, c]
                    beam_s[h, i, a], beam_x[h, i, a] = act_s[h, c], act_x[h, c]
            score[i] = child_score[c]
            parents[step, i] = e
            choices[step, i] = a
            rewards_kept[step, i] = reward[c]
        size = found
    best = np.argmax(score[:size])
    plan_actions = np.empty(horizon, dtype=np.int64)
    plan_rewards = np.empty(horizon)
    for step in range(horizon - 1, -1, -1):
        plan_actions[step] = choices[step, best]
        plan_rewards[step] = rewards_kept[step, best]
        best = parents[step, best]
    return plan_actions, plan_rewards


# States are hashed exactly: a sum modulo 2**61 of one term per (hypothesis, neuron),
# so that a child's hash is its do-nothing sibling's with the stimulated neuron's term
# replaced, whatever the order of the sum. Equal states (equal state_signature_rows rows)
# have equal hashes; equal hashes are checked whole. (Compiled, the products wrap at
# 2**64; as plain Python they do not: their low 61 bits, all that is kept, agree.)
_HASH_MASK = 2**61 - 1
_HASH_VOLTAGE_CAP = 4e18  # rounded potentials are clipped here to fit an int64


def _signature(v, refractory, since, released, interval, out):
    """Write into ``out`` [4] what state_signature_rows keeps of one neuron's state."""
    out[0] = np.rint(v / VOLTAGE_RESOLUTION_MV)
    out[1] = refractory
    out[2] = min(since, interval)
    out[3] = released


def _term(position, key, multipliers):
    """The hash term of one neuron's :func:`_signature` ``key`` at ``position``."""
    q = min(max(key[0], -_HASH_VOLTAGE_CAP), _HASH_VOLTAGE_CAP)
    u = int(q) * 1000003 + int(key[1])
    u = u * 1000003 + int(key[2])
    u = u * 2 + int(key[3])
    return (u * int(multipliers[position])) & _HASH_MASK


def _same_child(c, d, actions, none_key, act_key):
    """Whether children c and d have equal :func:`state_signature_rows` rows: only the
    stimulated neurons can differ between children of one entry."""
    n_actions, n = actions.shape[0], none_key.shape[3]
    e_c, a_c = c // n_actions, actions[c % n_actions]
    e_d, a_d = d // n_actions, actions[d % n_actions]
    for h in range(none_key.shape[0]):
        for j in range(n):
            if e_c == e_d and j != a_c and j != a_d:
                continue
            for f in range(4):
                key_c = act_key[h, c, f] if j == a_c else none_key[h, e_c, f, j]
                key_d = act_key[h, d, f] if j == a_d else none_key[h, e_d, f, j]
                if key_c != key_d:
                    return False
    return True


_signature = numba.njit(inline="always")(_signature)
_term = numba.njit(inline="always")(_term)
_same_child = numba.njit(cache=True, nogil=True)(_same_child)
_search = numba.njit(cache=True, nogil=True)(_search)
