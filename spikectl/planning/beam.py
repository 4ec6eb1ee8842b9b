"""Beam search over action sequences with the simulator's own step (the planner's core).

The planner never has its own copy of the dynamics: it steps each beam entry with the
kernel's :func:`spikectl.neuron.kernel.step_network` (the step
:func:`spikectl.neuron.simulator.advance` runs), doing nothing, and every other action
with :func:`spikectl.neuron.kernel.step_neuron` on the stimulated neuron (an action
enters the step only through its own neuron). The search is one compiled function
(Numba, :mod:`spikectl.planning.beam_kernel`): the same search as the NumPy one it
replaced (issue 24, part 4; the same plans, tests/test_planning_reference.py), without
NumPy's per-call overhead, which was nearly all of its time (a re-plan of 20
steps at width 32: 8.0 ms -> 0.33 ms at n = 8; docs/benchmarks.md). Two facts of the model
(docs/model.md) make a beam search strong here:

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
from spikectl.neuron.simulator import SimulatorState
from spikectl.planning.beam_kernel import VOLTAGE_RESOLUTION_MV, search


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
        """n, the number of neurons of the modelled networks."""
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
        """The sum of the plan's predicted step rewards."""
        return float(self.rewards.sum())


def state_signature_rows(
    state: SimulatorState, release_interval: int, hypotheses: int, entries: int
) -> np.ndarray:
    """[entries, K * 4n] float64 rows, equal exactly for beam entries the dynamics
    cannot tell apart (under every hypothesis; state rows are hypothesis-major)."""
    parts = np.concatenate(
        [
            np.round(state.voltage_mV / VOLTAGE_RESOLUTION_MV),
            state.refractory_left,
            np.minimum(state.steps_since_release, release_interval),
            state.released,
        ],
        axis=1,
    )  # [K * E, 4n]
    parts = parts.reshape(hypotheses, entries, -1).transpose(1, 0, 2).reshape(entries, -1)
    return np.ascontiguousarray(parts, dtype=np.float64)  # [E, K * 4n]


def take_states(state: SimulatorState, rows: np.ndarray) -> SimulatorState:
    return SimulatorState(
        state.voltage_mV[rows], state.refractory_left[rows],
        state.steps_since_release[rows], state.released[rows],
    )  # fmt: skip


_REWARDS: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def _step_rewards(pattern: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`step_rewards` of a pattern, kept (a controller re-plans one pattern often)."""
    key = pattern.tobytes()
    rewards = _REWARDS.get(key)
    if rewards is None:
        if len(_REWARDS) >= 1024:
            _REWARDS.clear()
        rewards = _REWARDS[key] = step_rewards(pattern)
    return rewards


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
    reward_if_spike, reward_if_silent = _step_rewards(pattern)
    actions, rewards = search(model, start, (reward_if_spike, reward_if_silent), start_step,
                              end, width)  # fmt: skip
    return Plan(actions, rewards)
