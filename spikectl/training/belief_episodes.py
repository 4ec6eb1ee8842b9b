"""Labelled episodes for the amortised belief (issue 61): generated networks, a behaviour
mix of actions, the batched simulator, and the truth the belief is trained against.

A batch is ``batch`` networks of one size drawn by the generator's topology rule
(docs/model.md: neurons on a line, connection probability by distance, 4:1 excitatory)
with a target among the neurons that have an excitatory input (the generator's rule;
the target pattern is not drawn: the belief never reads it). Each episode's actions come
from the behaviour mix (:class:`BehaviourMix`), the whole batch is simulated in one call
of :func:`spikectl.neuron.simulator.simulate`, and the label of neuron i is the class of
G[i, target] (:data:`~spikectl.agents.amortised_belief.CLASSES`). Every draw comes from
the generator passed in.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from spikectl.agents.amortised_belief import belief_features
from spikectl.contexts.generation import (
    connection_probability,
    generate_topology,
    target_candidates,
)
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, simulate


@dataclass(frozen=True)
class BehaviourMix:
    """How a batch's episodes act: each episode draws a stimulation rate uniformly in
    [``min_rate``, ``max_rate``]; each step stimulates a uniformly drawn neuron other than
    the target with that probability and else does nothing (random single-neuron probes);
    with probability ``stretch_probability`` an episode also holds still (does nothing)
    for one stretch of ``stretch_steps`` (min, max) steps at a random start."""

    min_rate: float = 0.05
    max_rate: float = 1.0
    stretch_probability: float = 0.3
    stretch_steps: tuple[int, int] = (5, 20)

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_rate <= self.max_rate <= 1.0:
            raise ValueError(
                f"BehaviourMix needs 0 <= min_rate <= max_rate <= 1, got "
                f"{self.min_rate}, {self.max_rate}"
            )
        if not 0.0 <= self.stretch_probability <= 1.0:
            raise ValueError(
                f"BehaviourMix.stretch_probability must lie in [0, 1], got "
                f"{self.stretch_probability}"
            )
        low, high = self.stretch_steps
        if not 1 <= low <= high:
            raise ValueError(f"BehaviourMix.stretch_steps must be 1 <= min <= max, got {low, high}")

    def actions(self, rng: np.random.Generator, n_neurons: int, targets: np.ndarray,
                episode_length: int) -> np.ndarray:  # fmt: skip
        """int64 [B, T] actions for episodes whose targets are ``targets`` [B]."""
        batch = targets.shape[0]
        rate = rng.uniform(self.min_rate, self.max_rate, size=(batch, 1))  # [B, 1]
        stimulate = rng.random((batch, episode_length)) < rate  # [B, T]
        # A uniform neuron other than the target: draw among n - 1 and skip the target.
        neuron = rng.integers(0, n_neurons - 1, size=(batch, episode_length))  # [B, T]
        neuron = neuron + (neuron >= targets[:, None])
        actions = np.where(stimulate, neuron, DO_NOTHING)
        low, high = self.stretch_steps
        stretched = rng.random(batch) < self.stretch_probability  # [B]
        length = rng.integers(low, high + 1, size=batch)  # [B]
        start = rng.integers(0, episode_length, size=batch)  # [B]
        steps = np.arange(episode_length)[None, :]  # [1, T]
        still = stretched[:, None] & (steps >= start[:, None]) & (steps < (start + length)[:, None])
        return np.where(still, DO_NOTHING, actions).astype(np.int64)


class BeliefBatch(NamedTuple):
    """A batch of labelled episodes of one size n."""

    features: np.ndarray
    """float32 [B, T, n, F] (:func:`~spikectl.agents.amortised_belief.belief_features`)."""
    labels: np.ndarray
    """int64 [B, n]: the class of G[i, target] (0 none, 1 excitatory, 2 inhibitory)."""
    is_target: np.ndarray
    """bool [B, n]: the target's own row (no label)."""
    prior: np.ndarray
    """float64 [B, n]: the generator's connection probability for (i, target) by distance,
    0 for the target: the base rate, what is known with no evidence."""
    weights: np.ndarray
    """int8 [B, n, n]: the networks (the truth, for comparisons)."""
    actions: np.ndarray
    """int64 [B, T]: the actions taken."""
    voltages: np.ndarray
    """float64 [B, T, n]: the observed potentials."""


def draw_networks(
    rng: np.random.Generator, n_neurons: int, batch: int
) -> tuple[np.ndarray, np.ndarray]:
    """(weights int8 [B, n, n], targets int64 [B]): the generator's topologies, each
    target uniform among the neurons with an excitatory input (a topology without one is
    redrawn, as the generator does)."""
    weights = np.empty((batch, n_neurons, n_neurons), dtype=np.int8)
    targets = np.empty(batch, dtype=np.int64)
    for b in range(batch):
        while True:
            topology = generate_topology(n_neurons, rng)
            candidates = target_candidates(topology)
            if candidates.size:
                break
        weights[b] = topology
        targets[b] = rng.choice(candidates)
    return weights, targets


def belief_batch(
    rng: np.random.Generator,
    n_neurons: int,
    batch: int,
    episode_length: int = 60,
    behaviour: BehaviourMix | None = None,
    params: NeuronParams | None = None,
) -> BeliefBatch:
    """``batch`` labelled episodes of ``n_neurons`` neurons under ``behaviour``."""
    behaviour = BehaviourMix() if behaviour is None else behaviour
    params = NeuronParams() if params is None else params
    weights, targets = draw_networks(rng, n_neurons, batch)
    actions = behaviour.actions(rng, n_neurons, targets, episode_length)  # [B, T]
    voltages, spikes = simulate(weights, actions, params)  # [B, T, n] each
    features = belief_features(voltages, spikes, actions, targets, params)
    rows = np.arange(batch)
    column = weights[rows, :, targets]  # [B, n]: G[i, target]
    labels = np.where(column > 0, 1, np.where(column < 0, 2, 0)).astype(np.int64)
    neurons = np.arange(n_neurons)
    is_target = neurons[None, :] == targets[:, None]  # [B, n]
    prior = np.where(
        is_target, 0.0, connection_probability(np.abs(neurons[None, :] - targets[:, None]))
    )
    return BeliefBatch(features, labels, is_target, prior, weights, actions, voltages)
