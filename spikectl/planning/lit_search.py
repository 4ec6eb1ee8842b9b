"""Beam search through the ChR2 actuator: the planner's state is the network's and the opsin's.

With ``Extensions(actuator="chr2")`` (docs/extensions.md, "The opsin actuator") an action
lights one neuron's ChR2 for 1 ms; the channel's occupancies (C1, O1, O2 per neuron)
carry the light's effect into the following steps. A plan for the pulse is wrong there
(a pulse makes its neuron spike in the same step; a light pulse opens channels whose
current drives the neuron from the next step on, for ~10 ms), so this search plays the
environment's own step: :func:`~spikectl.neuron.opsin.illuminate_kernel` (the drive of
the step from the occupancies and potentials at its start, then the occupancies through
the step under the light or in the dark) followed by
:func:`~spikectl.neuron.simulator.advance` with that drive as the step's input, the
simulator's action being none, exactly as the environments do.

Two facts shape the ranking. The light of step t does not change step t (its drive was
fixed at the step's start), so every child of a beam entry has the same network state
after t and differs only in the lit neuron's occupancies. And the target, never lit,
spikes at t + 1 and t + 2 whatever the light does from t + 1 on (the light of t + 1
drives at t + 2, its neuron's spike reaches the target at t + 3): those two rewards are
committed once the action of t is chosen. Each child is ranked by its reward so far plus
the return of doing nothing from then on over ``rollout`` steps (at least the two
committed; a feasible continuation, so a lower bound on what the child can still earn
in that window), the target's depolarisation breaking ties; duplicates (states equal at
the planner's resolution) are merged, and ``width`` distinct children are kept.

The occupancies depend on the light alone (not on the potentials), so they are the same
under every hypothesis about the weights; the search keeps them per hypothesis anyway,
in the simulator state's row order, so that one step call covers every row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.neuron.extensions import Extensions
from spikectl.neuron.opsin import OpsinActuator, illuminate_kernel
from spikectl.neuron.simulator import DO_NOTHING, DrawnInputs, SimulatorState, advance
from spikectl.planning.beam import Plan, PlanningModel, _step_rewards
from spikectl.planning.beam_kernel import VOLTAGE_RESOLUTION_MV, multipliers

OCCUPANCY_RESOLUTION = 1e-12
"""Occupancies are compared at this resolution when duplicate states are merged."""
DEFAULT_ROLLOUT_STEPS = 24
"""Steps of doing nothing each child is scored over: the committed two and the ~10 ms
burst a pulse drives, twice over (on the first 30 paper test networks at width 64: 2
steps 0.799, 12 0.924, 24 0.932, to the episode's end 0.923)."""
_TIE_BREAK = 1e-6  # weight of the target's depolarisation (mV) in the ranking


@dataclass
class Occupancies:
    """The opsins' state of a batch of networks: [B, n] fractions in C1, O1, O2."""

    c1: np.ndarray
    o1: np.ndarray
    o2: np.ndarray

    @classmethod
    def at_rest(cls, batch: int, n_neurons: int) -> Occupancies:
        """Every channel closed in C1."""
        shape = (batch, n_neurons)
        return cls(np.ones(shape), np.zeros(shape), np.zeros(shape))

    def copy(self) -> Occupancies:
        return Occupancies(self.c1.copy(), self.o1.copy(), self.o2.copy())

    def take(self, rows: np.ndarray) -> Occupancies:
        return Occupancies(self.c1[rows], self.o1[rows], self.o2[rows])


def planned_light(extensions: Extensions | None) -> float | None:
    """The fibre-tip irradiance (mW/mm^2) a planner plans the light of, for an environment
    with ``extensions``: None where the actuator is the paper's pulse."""
    if extensions is None or not extensions.lit:
        return None
    return float(extensions.light_irradiance_mW_per_mm2)


def lit_step(
    model: PlanningModel,
    opsin: OpsinActuator,
    state: SimulatorState,
    occupancies: Occupancies,
    lit: np.ndarray,
    weights: np.ndarray,
) -> np.ndarray:
    """Advance ``state`` and ``occupancies`` (B rows) in place by one step, neuron
    ``lit[b]`` (-1: none) of row b under light, on ``weights`` [B or 1, n, n]; returns
    the step's spikes [B, n] (the environments' step with the opsin actuator)."""
    batch, n = state.voltage_mV.shape
    drive = np.empty((batch, 1, n))
    illuminate_kernel(occupancies.c1, occupancies.o1, occupancies.o2, state.voltage_mV,
                      np.ascontiguousarray(lit, dtype=np.int64), opsin.dark_map,
                      opsin.light_map, opsin.mV_per_pA, drive, False)  # fmt: skip
    spikes = np.empty((batch, 1, n), dtype=bool)
    advance(state, weights, np.full((batch, 1), DO_NOTHING, dtype=np.int64), model.params,
            np.empty((batch, 1, n)), spikes, model.neurons, DrawnInputs(None, drive))  # fmt: skip
    return spikes[:, 0]


def lit_state_after(
    model: PlanningModel,
    opsin: OpsinActuator,
    state: SimulatorState,
    occupancies: Occupancies,
    actions: np.ndarray,
) -> tuple[SimulatorState, Occupancies]:
    """Copies of ``state`` and ``occupancies`` (one row per hypothesis of ``model``)
    stepped through the simulator actions ``actions`` [T] (the light they shine)."""
    state, occupancies = state.copy(), occupancies.copy()
    lit = np.empty(model.hypotheses, dtype=np.int64)
    for action in np.asarray(actions, dtype=np.int64):
        lit[:] = action
        lit_step(model, opsin, state, occupancies, lit, model.weights)
    return state, occupancies


def _rows(state: SimulatorState, rows: np.ndarray) -> SimulatorState:
    return SimulatorState(state.voltage_mV[rows], state.refractory_left[rows],
                          state.steps_since_release[rows], state.released[rows])  # fmt: skip


def _signature(state, occupancies, interval, hypotheses, entries) -> np.ndarray:
    """int64 [entries] hashes, equal for states the search cannot tell apart (the
    state at the planner's resolutions, times fixed random odd multipliers, summed with
    wrap-around: a collision of two distinct states is a ~2^-64 event)."""
    parts = np.concatenate([
        np.round(state.voltage_mV / VOLTAGE_RESOLUTION_MV), state.refractory_left,
        np.minimum(state.steps_since_release, interval), state.released,
        np.round(occupancies.c1 / OCCUPANCY_RESOLUTION),
        np.round(occupancies.o1 / OCCUPANCY_RESOLUTION),
        np.round(occupancies.o2 / OCCUPANCY_RESOLUTION),
    ], axis=1)  # fmt: skip
    parts = parts.reshape(hypotheses, entries, -1).transpose(1, 0, 2).reshape(entries, -1)
    return (parts.astype(np.int64) * multipliers(parts.shape[1])).sum(axis=1)


def lit_beam_search(
    model: PlanningModel,
    opsin: OpsinActuator,
    start: tuple[SimulatorState, Occupancies],
    pattern: np.ndarray,
    start_step: int = 0,
    width: int = 64,
    horizon: int | None = None,
    rollout: int = DEFAULT_ROLLOUT_STEPS,
) -> Plan:
    """The best light sequence found from ``start`` (the network's and the opsins' state
    before step ``start_step``, one row per hypothesis of ``model``) over steps
    ``start_step`` .. end - 1 (end: the episode's, or ``horizon`` steps on), ranked by
    the mean return over the hypotheses; ``opsin`` gives the light's maps (its own state
    is not used). Ties go to the lower child (do nothing first), so it is deterministic."""
    if width < 1 or rollout < 2:
        raise ValueError(f"width must be >= 1 and rollout >= 2, got {width}, {rollout}")
    pattern = np.asarray(pattern, dtype=bool)
    if not 0 <= start_step < pattern.shape[0]:
        raise ValueError(f"start_step must lie in 0..{pattern.shape[0] - 1}, got {start_step}")
    end = pattern.shape[0] if horizon is None else min(pattern.shape[0], start_step + horizon)
    if_spike, if_silent = _step_rewards(pattern)
    k, target = model.hypotheses, model.target
    actions = np.asarray(model.actions, dtype=np.int64)
    n_actions = actions.size
    interval = int(min(model.params.min_release_interval_steps, 2**30))
    resting = model.params.v_rest_mV
    state, occupancies = start[0].copy(), start[1].copy()
    if k > 1 and state.voltage_mV.shape[0] == 1:  # one start for every hypothesis
        state, occupancies = (
            _rows(state, np.zeros(k, np.int64)),
            occupancies.take(np.zeros(k, np.int64)),
        )
    score, size = np.zeros(1), 1
    parents, choices, step_rewards = [], [], []
    for t in range(start_step, end):
        # The step itself is the same for every child of an entry: step the entries once.
        before = occupancies.copy()
        weights = np.repeat(model.weights, size, axis=0) if k > 1 else model.weights
        spikes = lit_step(model, opsin, state, occupancies,
                          np.full(k * size, DO_NOTHING, dtype=np.int64), weights)  # fmt: skip
        reward = np.where(spikes[:, target], if_spike[t], if_silent[t])
        reward = reward.reshape(k, size).mean(axis=0)  # [E]
        # The children: each entry's state, the lit neuron's occupancies under the light.
        children = size * n_actions
        rows = np.repeat(np.arange(k * size), n_actions)  # hypothesis-major, child-minor
        child_state, child_occ = _rows(state, rows), occupancies.take(rows)
        lit = np.tile(actions, k * size)
        on = np.flatnonzero(lit >= 0)
        m = opsin.light_map
        x0, x1, x2 = (part[rows[on], lit[on]] for part in (before.c1, before.o1, before.o2))
        for out, r in ((child_occ.c1, 0), (child_occ.o1, 1), (child_occ.o2, 2)):
            out[on, lit[on]] = m[r, 0] * x0 + m[r, 1] * x1 + m[r, 2] * x2 + m[r, 3]
        child_score = np.repeat(score + reward, n_actions)  # [C]
        # Rank: reward so far + doing nothing over the next `rollout` steps.
        ahead = np.zeros(children)
        probe, probe_occ = child_state.copy(), child_occ.copy()
        child_weights = np.repeat(model.weights, children, axis=0) if k > 1 else model.weights
        dark = np.full(k * children, DO_NOTHING, dtype=np.int64)
        for s in range(t + 1, min(end, t + 1 + rollout)):
            fired = lit_step(model, opsin, probe, probe_occ, dark, child_weights)[:, target]
            ahead += np.where(fired, if_spike[s], if_silent[s]).reshape(k, children).mean(0)
        depolarisation = np.clip(probe.voltage_mV[:, target] - resting, -20.0, 20.0)
        ranking = child_score + ahead + _TIE_BREAK * depolarisation.reshape(k, children).mean(0)
        order = np.argsort(-ranking, kind="stable")
        keys = _signature(child_state, child_occ, interval, k, children)[order]
        _, first = np.unique(keys, return_index=True)
        kept = order[np.sort(first)[:width]]
        parents.append(kept // n_actions)
        choices.append(actions[kept % n_actions])
        step_rewards.append(np.repeat(reward, n_actions)[kept])
        score, size = child_score[kept], kept.size
        chosen_rows = (np.arange(k)[:, None] * children + kept[None]).ravel()
        state, occupancies = _rows(child_state, chosen_rows), child_occ.take(chosen_rows)
    best = int(np.argmax(score))
    plan_actions = np.empty(end - start_step, dtype=np.int64)
    plan_rewards = np.empty(end - start_step)
    for i in range(end - start_step - 1, -1, -1):
        plan_actions[i], plan_rewards[i] = choices[i][best], step_rewards[i][best]
        best = int(parents[i][best])
    return Plan(plan_actions, plan_rewards)


def lit_spikes(model: PlanningModel, opsin: OpsinActuator, landing: np.ndarray) -> np.ndarray:
    """[N, n] the spikes of ``model``'s first network from rest when the light lands as
    ``landing`` [N] (simulator actions, -1: none): the environment's raster."""
    state = SimulatorState.at_rest(1, model.n_neurons, model.params)
    occupancies = Occupancies.at_rest(1, model.n_neurons)
    weights = np.ascontiguousarray(model.weights[:1])
    lit = np.empty(1, dtype=np.int64)
    raster = np.empty((len(landing), model.n_neurons), dtype=bool)
    for t, action in enumerate(np.asarray(landing, dtype=np.int64)):
        lit[0] = action
        raster[t] = lit_step(model, opsin, state, occupancies, lit, weights)[0]
    return raster


def tracked_occupancies(opsin: OpsinActuator, m: int) -> Occupancies:
    """An opsin's tracked occupancies (its first row's n neurons) as one row of ``m >= n``
    neurons: the planner's virtual relay neurons, never lit, at rest."""
    occupancies = Occupancies.at_rest(1, m)
    n = opsin.c1.shape[1]
    occupancies.c1[0, :n], occupancies.o1[0, :n] = opsin.c1[0], opsin.o1[0]
    occupancies.o2[0, :n] = opsin.o2[0]
    return occupancies


def network_model(weights: np.ndarray, params, neurons: np.ndarray | None) -> PlanningModel:
    """A :class:`PlanningModel` of one network's ``weights`` [m, m] to step (no target,
    no actions: :func:`lit_step` and :func:`lit_state_after` read neither)."""
    return PlanningModel(np.ascontiguousarray(weights[None]), 0, np.empty(0, dtype=np.int64),
                         params, neurons)  # fmt: skip
