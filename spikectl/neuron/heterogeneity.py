"""Heterogeneous neurons and hidden neurons of one network: the context-level data that
:class:`spikectl.neuron.extensions.Extensions` draws with the contexts (docs/extensions.md).

:class:`Heterogeneity` holds one network's per-neuron and per-synapse parameters;
:func:`draw_hidden` draws which neurons are hidden. Both are saved with the context set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Heterogeneity:
    """Per-neuron and per-synapse parameters of one network (heterogeneous neurons)."""

    thresholds_mV: np.ndarray
    """[n] float64 spike threshold V_th of each neuron."""
    time_constants_ms: np.ndarray
    """[n] float64 membrane time constant R C of each neuron."""
    synaptic_scale: np.ndarray
    """[n, n] float64 factor on w_in of each synapse i -> j (1 where there is none)."""

    def __post_init__(self) -> None:
        thresholds = np.array(self.thresholds_mV, dtype=np.float64)
        time_constants = np.array(self.time_constants_ms, dtype=np.float64)
        scale = np.array(self.synaptic_scale, dtype=np.float64)
        n = thresholds.shape[0] if thresholds.ndim == 1 else -1
        if thresholds.ndim != 1 or time_constants.shape != (n,) or scale.shape != (n, n):
            raise ValueError(
                "heterogeneity needs thresholds_mV [n], time_constants_ms [n] and "
                f"synaptic_scale [n, n]; got {thresholds.shape}, {time_constants.shape}, "
                f"{scale.shape}"
            )
        for name, array in (("thresholds_mV", thresholds), ("time_constants_ms", time_constants),
                            ("synaptic_scale", scale)):  # fmt: skip
            if not np.isfinite(array).all():
                raise ValueError(f"heterogeneity {name} must be finite")
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        if (time_constants <= 0).any() or (scale < 0).any():
            raise ValueError("heterogeneity time constants must be > 0 and synaptic scales >= 0")

    @property
    def n_neurons(self) -> int:
        """n, the number of neurons these values are drawn for."""
        return self.thresholds_mV.shape[0]

    def simulate_kwargs(self) -> dict[str, np.ndarray]:
        """The keyword arguments of :func:`spikectl.simulate` for these neurons."""
        return {
            "thresholds_mV": self.thresholds_mV,
            "membrane_time_constants_ms": self.time_constants_ms,
            "synaptic_scale": self.synaptic_scale,
        }

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Heterogeneity):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, name), getattr(other, name))
            for name in ("thresholds_mV", "time_constants_ms", "synaptic_scale")
        )

    __hash__ = None


def draw_hidden(
    rng: np.random.Generator, n_neurons: int, target: int, count: int
) -> np.ndarray | None:
    """``count`` hidden neurons drawn uniformly among the non-targets, sorted; None for 0."""
    if count == 0:
        return None
    candidates = np.delete(np.arange(n_neurons), target)
    return np.sort(rng.choice(candidates, size=count, replace=False)).astype(np.int64)
