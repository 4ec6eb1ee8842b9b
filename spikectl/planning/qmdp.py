"""Choose an action by its expected return over networks that the evidence allows (QMDP).

Identify-and-plan plans on one estimate of the connectivity. Early in an episode that
estimate knows little, and a wanted target spike needs a *gamble*: stimulate the
neuron that most probably excites the target. This module values each candidate
action a at step t by its expected return over K networks G_k drawn from the
posterior, each continued by the best plan *for that network*:

    Q(a) = sum_k w_k [ r_k(t, a) + max over continuations of the return of G_k ] / sum_k w_k

the QMDP approximation (Littman, Cassandra & Kaelbling 1995): it assumes the network
is known after this step, so it values what an action does, not what it teaches.
The continuations are found by :func:`best_returns`, a beam search run for all
(network, first action) pairs at once, each with its own beam.

The weights w_k are what the evidence the Gaussian estimate does not use says about
G_k (:func:`context_likelihood`): the environment drew the target uniformly among the
neurons with an excitatory input, and drew the pattern from uniformly random actions,
so a spike wanted at step 1 means the first random action was an excitatory input of
the target.

QMDP alone never pays to learn (every network counts as known after one step), so
the policy adds :func:`synapse_entropy`, what a probe would teach about the target's
inputs, times a small weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.envs.env_support import step_rewards
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.prediction import one_step
from spikectl.neuron.simulator import DO_NOTHING, SimulatorState, advance
from spikectl.planning import portable
from spikectl.planning.beam import state_signature_rows, take_states

# Weight of the target's depolarisation (mV) in the ranking: breaks ties only (as in beam).
_TIE_BREAK = 1e-6
_PROJECTION_SEED = 20261122
# Q values this close to the best count as tied (float round-off of the weighted mean).
_TIE_TOLERANCE = 1e-12


@dataclass(frozen=True)
class Episode:
    """The episode a decision is taken in: what every valued action is played against.

    Attributes:
        pattern: [N] bool target pattern of the episode.
        target: the rewarded neuron.
        actions: int64 [A] the legal simulator actions, do nothing (-1) first.
        params: the neuron parameters.
    """

    pattern: np.ndarray
    target: int
    actions: np.ndarray
    params: NeuronParams


@dataclass(frozen=True)
class QMDPSettings:
    """How the expected-return choice values actions (the decision rule's "gamble").

    Attributes:
        networks: K, the networks drawn from the estimate.
        information: the bonus, in units of return per nat, for stimulating a ready
            neuron whose synapse onto the target is unknown (the entropy of that synapse
            over the K networks): QMDP alone values no information and waits (chosen on
            validation networks, docs/baselines.md).
        horizon: steps each action is valued over, its own included.
        width: beam width of the best continuation on each drawn network.
        candidates: at most this many actions are valued (do nothing, the probe and the
            likeliest excitatory inputs of the target), for large n.
    """

    networks: int = 16
    information: float = 0.03
    horizon: int = 10
    width: int = 8
    candidates: int = 8

    def __post_init__(self) -> None:
        for name, least in (("networks", 1), ("horizon", 1), ("width", 1), ("candidates", 2)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
        if isinstance(self.information, bool) or not self.information >= 0:
            raise ValueError(f"information must be >= 0, got {self.information!r}")


def best_returns(
    weights: np.ndarray,
    start: SimulatorState,
    episode: Episode,
    start_step: int,
    horizon: int,
    width: int,
) -> np.ndarray:
    """[P] the best return over steps start_step .. start_step + horizon - 1 found for
    each of P independent problems (problem p: network ``weights[p]`` from row p of
    ``start``), by a beam of ``width`` distinct states per problem.

    Args:
        weights: [P, n, n] int8 or float64 signed weights in units of w_in.
        start: the P start states (advanced copies are made; ``start`` is not changed).
        episode: the pattern, target, legal actions and neuron model.
        start_step: the first step searched.
        horizon: steps searched (cut at the episode's end); 0 returns zeros.
        width: states kept per problem and step.
    """
    actions, target, params = episode.actions, episode.target, episode.params
    problems = weights.shape[0]
    pattern = np.asarray(episode.pattern, dtype=bool)
    end = min(pattern.shape[0], start_step + horizon)
    if end <= start_step:
        return np.zeros(problems)
    reward_if_spike, reward_if_silent = step_rewards(pattern)
    n, n_actions = weights.shape[-1], actions.shape[0]
    interval = min(params.min_release_interval_steps, 2**30)
    projection = np.random.default_rng(_PROJECTION_SEED).standard_normal(4 * n)
    beam = take_states(start, np.arange(problems))
    problem = np.arange(problems)  # [E] the problem of each beam entry, ascending
    score = np.zeros(problems)
    for t in range(start_step, end):
        rows = np.repeat(np.arange(problem.shape[0]), n_actions)  # [C]
        children = take_states(beam, rows)
        child_problem = problem[rows]  # [C]
        voltage = np.empty((rows.shape[0], 1, n))
        spikes = np.empty((rows.shape[0], 1, n), dtype=bool)
        child_actions = np.ascontiguousarray(np.tile(actions, problem.shape[0])[:, None])
        child_weights = np.ascontiguousarray(weights[child_problem])
        advance(children, child_weights, child_actions, params, voltage, spikes)
        spiked = spikes[:, 0, target]
        child_score = score[rows] + np.where(spiked, reward_if_spike[t], reward_if_silent[t])
        ranking = child_score.copy()
        if t + 1 < end:
            # The target's next step is committed now (its input takes one step).
            _, committed = one_step(children, child_weights, DO_NOTHING, params, neuron=target)
            ranking += np.where(committed, reward_if_spike[t + 1], reward_if_silent[t + 1])
        depolarisation = children.voltage_mV[:, target] - params.v_rest_mV
        ranking += _TIE_BREAK * np.clip(depolarisation, -20.0, 20.0)
        # Problem-major, best first; then the first of each (problem, state) and at
        # most ``width`` per problem.
        order = np.lexsort((-ranking, child_problem))
        signatures = state_signature_rows(children, interval, 1, rows.shape[0])
        hashed = portable.matmul(signatures, projection)[order]
        ordered_problem = child_problem[order]
        by_state = np.lexsort((np.arange(order.shape[0]), hashed, ordered_problem))
        first = np.ones(by_state.shape[0], dtype=bool)
        first[1:] = (np.diff(ordered_problem[by_state]) != 0) | (np.diff(hashed[by_state]) != 0)
        distinct = np.sort(by_state[first])  # positions in ``order``
        kept_problem = ordered_problem[distinct]
        rank = np.arange(distinct.shape[0]) - np.searchsorted(kept_problem, kept_problem)
        kept = order[distinct[rank < width]]
        beam, problem, score = take_states(children, kept), child_problem[kept], child_score[kept]
    best = np.full(problems, -np.inf)
    np.maximum.at(best, problem, score)
    return best


def expected_returns(
    networks: np.ndarray,
    network_weights: np.ndarray,
    state: SimulatorState,
    candidates: np.ndarray,
    episode: Episode,
    step: int,
    settings: QMDPSettings,
) -> np.ndarray:
    """[A0] Q(a) for each candidate action: the w-weighted mean over the K networks of
    the reward of ``step`` after a plus the best return of the next ``horizon - 1``
    steps on that network.

    Args:
        networks: [K, n, n] int8 networks drawn from the posterior.
        network_weights: [K] non-negative importance weights (not all 0).
        state: the current simulator state (batch of one), before ``step``.
        candidates: int64 [A0] the actions to value (legal ones).
        episode: the episode (its legal actions are the continuations').
        step: the current step.
        settings: ``horizon`` (steps valued, this one included) and ``width`` (beam
            width of each continuation).
    """
    pattern, target, params = episode.pattern, episode.target, episode.params
    k, n_candidates = networks.shape[0], candidates.shape[0]
    total = float(np.sum(network_weights))
    if not total > 0:
        raise ValueError("network_weights must have a positive sum")
    weights = np.ascontiguousarray(np.repeat(networks, n_candidates, axis=0))  # [K * A0, n, n]
    start = take_states(state, np.zeros(k * n_candidates, dtype=np.int64))
    n = networks.shape[-1]
    voltage = np.empty((k * n_candidates, 1, n))
    spikes = np.empty((k * n_candidates, 1, n), dtype=bool)
    first = np.ascontiguousarray(np.tile(candidates, k)[:, None])  # [K * A0, 1]
    advance(start, weights, first, params, voltage, spikes)
    reward_if_spike, reward_if_silent = step_rewards(np.asarray(pattern, dtype=bool))
    values = np.where(spikes[:, 0, target], reward_if_spike[step], reward_if_silent[step])
    values = values + best_returns(
        weights, start, episode, step + 1, settings.horizon - 1, settings.width
    )
    return portable.matmul(network_weights / total, values.reshape(k, n_candidates))  # [A0]


def context_likelihood(networks: np.ndarray, target: int, pattern: np.ndarray,
                       n_actions: int) -> np.ndarray:  # fmt: skip
    """[K] P(target, pattern[1] | G_k) up to a constant: what the context generator's
    draws say about each network.

    The generator (spikectl.contexts.generate_context) draws the target uniformly among
    the neurons with an excitatory input (probability 1 / |candidates| if the target is
    one, else 0) and the pattern from ``n_actions`` uniformly random legal actions from
    rest; the target spikes at step 1 exactly when the first of them is one of its
    excitatory inputs (probability e / n_actions with e of them).
    """
    excitatory = networks > 0  # [K, n, n]
    candidates = excitatory.any(axis=1).sum(axis=1)  # [K]
    inputs = excitatory[:, :, target].sum(axis=1)  # [K]
    chosen = np.where(inputs > 0, 1.0 / np.maximum(candidates, 1), 0.0)
    first_spike = inputs / n_actions if pattern[1] else 1.0 - inputs / n_actions
    return chosen * first_spike


def synapse_entropy(columns: np.ndarray, network_weights: np.ndarray) -> np.ndarray:
    """[n] the entropy (nats) of each synapse i -> target over the K weighted networks.

    Args:
        columns: [K, n] the target's column of each network, in {-1, 0, +1}.
        network_weights: [K] non-negative weights (not all 0).
    """
    share_of = network_weights / np.sum(network_weights)  # [K]
    entropy = np.zeros(columns.shape[1])
    for value in (-1, 0, 1):
        share = portable.matmul(share_of, columns == value)  # [n]
        entropy -= share * portable.log(np.where(share > 0, share, 1.0))
    return entropy


def qmdp_action(
    networks: np.ndarray,
    excitation: np.ndarray,
    state: SimulatorState,
    teachable: np.ndarray,
    probe: int,
    episode: Episode,
    step: int,
    settings: QMDPSettings,
) -> int:
    """The legal action of highest Q (:func:`expected_returns`, the networks weighted by
    :func:`context_likelihood`) plus ``settings.information`` times the entropy of the
    stimulated neuron's synapse onto the target, where that neuron is ``teachable``.
    Ties go to ``probe``, then to do nothing.

    Args:
        networks: [K, n, n] int8 networks drawn from the estimate.
        excitation: [n] P(neuron excites the target), to pick the candidates when more
            than ``settings.candidates`` actions are legal (do nothing, the probe and the
            likeliest excitatory inputs are valued).
        state: the current simulator state (batch of one).
        teachable: [n] bool, neurons that release if they spike now and whose synapse
            onto the target the estimate does not know.
        probe: the action the probing rule would take (a legal action).
        episode: the pattern, target, legal actions (do nothing first) and the model.
        step: the current step.
        settings: the continuations' horizon and width, the bonus per nat and the most
            actions valued.
    """
    legal = np.asarray(episode.actions, dtype=np.int64)
    target = episode.target
    likelihood = context_likelihood(networks, target, episode.pattern, legal.shape[0])
    if not likelihood.sum() > 0:
        likelihood = np.ones(networks.shape[0])  # the estimate contradicts the context
    candidates = legal
    if legal.shape[0] > settings.candidates:
        neurons = legal[1:][np.argsort(-excitation[legal[1:]], kind="stable")]
        keep = dict.fromkeys([int(legal[0]), probe, *neurons.tolist()])
        candidates = np.array(list(keep)[: settings.candidates], dtype=np.int64)
    values = expected_returns(networks, likelihood, state, candidates, episode, step, settings)
    entropy = synapse_entropy(networks[:, :, target], likelihood)  # [n]
    neuron = np.maximum(candidates, 0)
    teaches = (candidates >= 0) & teachable[neuron]
    values = values + settings.information * np.where(teaches, entropy[neuron], 0.0)
    probe_value = values[np.flatnonzero(candidates == probe)[0]]
    if probe_value >= values.max() - _TIE_TOLERANCE:
        return int(probe)
    return int(candidates[np.argmax(values)])
