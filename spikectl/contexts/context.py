"""One context (docs/model.md): a network's hidden connectivity, the target neuron and
the spike pattern it must produce, plus the *witness*, an action sequence that produces
that pattern from rest. :class:`Context` validates and freezes what it is given; drawing
one is ``spikectl.contexts.generation``'s work.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikectl.neuron.extensions import Heterogeneity
from spikectl.neuron.params import NeuronParams
from spikectl.neuron.simulator import DO_NOTHING, as_weight_batch, simulate


@dataclass(frozen=True, eq=False)
class Context:
    """One task: hidden connectivity, the observable target and pattern, and a witness.

    Attributes:
        weights: [n, n] int8 signed connectivity, row = presynaptic (never observable).
        target: the neuron to control (a neuron index).
        pattern: [N] bool, the steps at which the target must spike.
        witness: [N] int16 actions (neuron indices) that produce ``pattern`` from rest,
            or None for a user-supplied pattern whose reachability is unknown.
        hidden: sorted int64 indices of the neurons that are simulated but neither
            observed nor stimulable (an extension), or None. Never the target.
        heterogeneity: per-neuron and per-synapse parameters (an extension), or None
            for the paper's identical neurons.
    """

    weights: np.ndarray
    target: int
    pattern: np.ndarray
    witness: np.ndarray | None = None
    hidden: np.ndarray | None = None
    heterogeneity: Heterogeneity | None = None

    def __post_init__(self) -> None:
        weights = as_weight_batch(self.weights)[0].astype(np.int8)
        n = weights.shape[0]
        if n < 2:
            raise ValueError(f"a context needs at least 2 neurons, got {n}")
        check_target(self.target, n)
        pattern = np.asarray(self.pattern)
        if pattern.ndim != 1:
            raise ValueError(f"pattern must be 1-D [episode_length], got shape {pattern.shape}")
        if not np.all(np.isin(pattern, (0, 1))):
            raise ValueError("pattern must contain only 0/1 or False/True")
        pattern = pattern.astype(bool)
        spikes = int(pattern.sum())
        if not 1 <= spikes <= pattern.size - 1:
            raise ValueError(
                f"pattern must have between 1 and {pattern.size - 1} spikes (the reward "
                f"divides by both counts), got {spikes}"
            )
        object.__setattr__(self, "weights", _readonly(weights))
        object.__setattr__(self, "target", int(self.target))
        object.__setattr__(self, "pattern", _readonly(pattern))
        self._check_extensions(n)
        if self.witness is not None:
            witness = np.asarray(self.witness)
            if witness.shape != pattern.shape or not np.issubdtype(witness.dtype, np.integer):
                raise ValueError(
                    f"witness must be integer actions of shape {pattern.shape}, "
                    f"got {witness.dtype} {witness.shape}"
                )
            if witness.min() < DO_NOTHING or witness.max() >= n:
                raise ValueError(f"witness actions must lie in -1..{n - 1}")
            if self.hidden is not None and np.isin(witness, self.hidden).any():
                raise ValueError("witness actions must not stimulate hidden neurons")
            object.__setattr__(self, "witness", _readonly(witness.astype(np.int16)))

    def _check_extensions(self, n: int) -> None:
        if self.hidden is not None:
            hidden = np.asarray(self.hidden)
            if hidden.ndim != 1 or (hidden.size and not np.issubdtype(hidden.dtype, np.integer)):
                raise ValueError(f"hidden must be a 1-D array of neuron indices, got {hidden!r}")
            hidden = np.unique(hidden.astype(np.int64))
            if hidden.size != np.asarray(self.hidden).size:
                raise ValueError("hidden neurons must be distinct")
            if hidden.size and (hidden.min() < 0 or hidden.max() >= n):
                raise ValueError(f"hidden neurons must be neuron indices in 0..{n - 1}")
            if self.target in hidden:
                raise ValueError(f"the target neuron {self.target} cannot be hidden")
            if n - hidden.size < 2:
                raise ValueError("at least 2 neurons must be observable (the target and one more)")
            object.__setattr__(self, "hidden", _readonly(hidden) if hidden.size else None)
        if self.heterogeneity is not None:
            if not isinstance(self.heterogeneity, Heterogeneity):
                raise TypeError(
                    f"heterogeneity must be a Heterogeneity or None, got {self.heterogeneity!r}"
                )
            if self.heterogeneity.n_neurons != n:
                raise ValueError(
                    f"heterogeneity is for {self.heterogeneity.n_neurons} neurons, not {n}"
                )

    @property
    def n_neurons(self) -> int:
        """n, the number of neurons (observable and hidden)."""
        return self.weights.shape[0]

    @property
    def episode_length(self) -> int:
        """N, the number of steps of an episode (the pattern's length)."""
        return self.pattern.shape[0]

    @property
    def observable(self) -> np.ndarray:
        """[k] increasing indices of the observable neurons (all n without hidden ones)."""
        everyone = np.arange(self.n_neurons)
        return everyone if self.hidden is None else np.setdiff1d(everyone, self.hidden)

    @property
    def n_observed(self) -> int:
        """k, the number of observable neurons."""
        return self.n_neurons - (0 if self.hidden is None else self.hidden.size)

    @property
    def observed_target(self) -> int:
        """The target's index among the observable neurons (what the agent sees)."""
        return int(np.searchsorted(self.observable, self.target))

    @property
    def agent_witness(self) -> np.ndarray | None:
        """The witness as environment actions (indices among the observable neurons)."""
        if self.witness is None or self.hidden is None:
            return self.witness
        observed = np.searchsorted(self.observable, self.witness)
        return np.where(self.witness >= 0, observed, DO_NOTHING).astype(np.int16)

    def simulate_kwargs(self) -> dict[str, np.ndarray]:
        """Keyword arguments of :func:`spikectl.simulate` for this network's neurons."""
        return {} if self.heterogeneity is None else self.heterogeneity.simulate_kwargs()

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Context):
            return NotImplemented
        return (
            self.target == other.target
            and np.array_equal(self.weights, other.weights)
            and np.array_equal(self.pattern, other.pattern)
            and _optional_equal(self.witness, other.witness)
            and _optional_equal(self.hidden, other.hidden)
            and self.heterogeneity == other.heterogeneity
        )

    __hash__ = None  # mutable-looking arrays inside; compare with ==

    def verify_witness(self, params: NeuronParams | None = None) -> bool:
        """True when replaying the witness from rest reproduces the pattern exactly."""
        if self.witness is None:
            return False
        witness = self.witness.astype(np.int64)
        _, spikes = simulate(self.weights, witness, params, **self.simulate_kwargs())
        return bool(np.array_equal(spikes[:, self.target], self.pattern))


def _optional_equal(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(a, b))


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array)  # a private copy, so the caller's array cannot change us
    array.flags.writeable = False
    return array


def check_target(target: int, n_neurons: int) -> None:
    if isinstance(target, (bool, np.bool_)) or not isinstance(target, (int, np.integer)):
        raise TypeError(f"target must be an integer neuron index, got {target!r}")
    if not 0 <= target < n_neurons:
        raise ValueError(f"target {target} is not a neuron index in 0..{n_neurons - 1}")
