"""The zero-based spaces and observations that both SB3 adapters write.

Shared by :class:`~spikectl.wrappers.sb3.SB3CompatibleEnv` (one environment) and
:class:`~spikectl.wrappers.sb3_vec_adapter.SB3VecEnv` (the batched one): the action
offset, the finite voltage bounds and the observation codec. Needs no SB3.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from spikectl.neuron.params import NEVER_RELEASES, NeuronParams

DO_NOTHING = 0
"""The zero-based action that stimulates no neuron (the base environment's -1)."""
ILLEGAL_ACTIONS = ("do_nothing", "raise")
"""What an illegal action (stimulating the target) does: nothing, or raise ValueError."""


def to_env_action(action: Any) -> Any:
    """Zero-based action(s) a -> the base environment's a - 1 (0 -> -1, do nothing)."""
    return action - 1


def from_env_action(action: Any) -> Any:
    """The base environment's action(s) a -> zero-based a + 1 (-1 -> 0, do nothing)."""
    return action + 1


def voltage_bounds_mV(
    params: NeuronParams, n_neurons: int, stochastic_release: bool = False
) -> tuple[float, float]:
    """Bounds (low, high) in mV on every potential a network of ``n_neurons`` can show.

    Per step a neuron at V moves to V - (V - V_rest) dt/(R C) + drive, where the drive
    is the stimulus (dt w_e / C) plus dt w_in / C per released presynaptic neuron; any
    of the n neurons (itself included, for hand-made contexts) may be presynaptic, with
    weight -1, 0 or +1.

    - high: a neuron that has not spiked is below V_th, and leaking towards rest only
      lowers it, so V < V_th + dt (w_e + n w_in) / C.
    - low: a neuron releases at most once every K = ``min_release_interval_steps``
      steps (K = 1 with stochastic release), so n inhibitory partners, each kicking
      as often as it can, leave at most sum_j n (dt w_in / C) (1 - dt/(R C))^(K j)
      below rest: V >= V_rest - n (dt w_in / C) / (1 - (1 - dt/(R C))^K).

    With the defaults and n = 8: (-777.3, 150.0). They hold exactly for the paper's
    model; heterogeneous neurons, background input and measurement noise
    (docs/extensions.md) can go beyond them, and the wrappers clip.
    """
    interval = 1 if stochastic_release else params.min_release_interval_steps
    synaptic_step_mV = params.synaptic_step_mV
    if interval == NEVER_RELEASES or (stochastic_release and params.release_scale == 0):
        synaptic_step_mV = 0.0
        interval = 1
    high = params.v_threshold_mV + params.stimulus_step_mV + n_neurons * synaptic_step_mV
    low = params.v_rest_mV - n_neurons * synaptic_step_mV / (
        1.0 - (1.0 - params.leak_per_step) ** interval
    )
    return low, high


def _float32_outward(low: float, high: float) -> tuple[np.float32, np.float32]:
    """float32 bounds that contain [low, high] (a cast alone may round inwards)."""
    low32, high32 = np.float32(low), np.float32(high)
    if low32 > low:
        low32 = np.nextafter(low32, np.float32(-np.inf))
    if high32 < high:
        high32 = np.nextafter(high32, np.float32(np.inf))
    return low32, high32


class SB3Observation:
    """The wrappers' observation space and the map from the base observation to it.

    Works on one observation or on a batch (leading axis, as the vector environment
    gives them). With ``flatten=False`` the base ``Dict`` with ``last_action`` in
    0..k (0: none, a: neuron a - 1) and the voltage in mV clipped to
    :func:`voltage_bounds_mV`. With ``flatten=True`` one float32 vector of
    3k + 3N + 2 entries:

    | slice          | entries                                                   |
    |----------------|-----------------------------------------------------------|
    | ``[0, k)``     | voltage as (V - V_rest) / (V_th - V_rest): 0 at rest, 1 at |
    |                | threshold; bounds scaled alike (-35.4, 11 for n = 8)       |
    | ``[k, 2k)``    | target, one-hot                                           |
    | ``[2k, 3k+1)`` | last action, one-hot over 0..k                            |
    | next N + 1     | step t, one-hot over 0..N                                 |
    | next N         | pattern                                                   |
    | next N         | pattern ahead: pattern[t + j], -1 past the end            |

    The pattern ahead repeats what pattern and step say, aligned with the current step,
    so that a policy without memory or attention can read the next wanted spikes.
    """

    def __init__(
        self,
        n_observed: int,
        n_neurons: int,
        episode_length: int,
        params: NeuronParams,
        stochastic_release: bool = False,
        flatten: bool = True,
    ) -> None:
        self.k = k = n_observed
        self.N = length = episode_length
        self.flatten = flatten
        self.v_rest_mV, self.v_threshold_mV = params.v_rest_mV, params.v_threshold_mV
        low, high = _float32_outward(*voltage_bounds_mV(params, n_neurons, stochastic_release))
        self.voltage_low_mV, self.voltage_high_mV = low, high
        self._ahead = np.arange(length)  # [N]
        if not flatten:
            self.space = spaces.Dict(
                {
                    "voltage": spaces.Box(low, high, (k,), np.float32),
                    "target": spaces.Discrete(k),
                    "pattern": spaces.MultiBinary(length),
                    "step": spaces.Discrete(length + 1),
                    "last_action": spaces.Discrete(k + 1),
                }
            )
            return
        size = 3 * k + 3 * length + 2
        lows = np.zeros(size, dtype=np.float32)
        highs = np.ones(size, dtype=np.float32)
        lows[:k], highs[:k] = _float32_outward(self._scaled(low), self._scaled(high))
        lows[-length:] = -1.0
        self.space = spaces.Box(lows, highs, (size,), np.float32)

    def _scaled(self, voltage_mV: Any) -> Any:
        return (voltage_mV - self.v_rest_mV) / (self.v_threshold_mV - self.v_rest_mV)

    def __call__(self, observation: dict[str, Any]) -> np.ndarray | dict[str, Any]:
        """The observation (or batch) of the base environment in this space."""
        voltage = np.clip(
            np.asarray(observation["voltage"], dtype=np.float32),
            self.voltage_low_mV,
            self.voltage_high_mV,
        )
        last_action = from_env_action(np.asarray(observation["last_action"], dtype=np.int64))
        if not self.flatten:
            batched = voltage.ndim == 2
            return {
                "voltage": voltage,
                "target": np.asarray(observation["target"], dtype=np.int64)
                if batched
                else int(observation["target"]),
                "pattern": np.asarray(observation["pattern"], dtype=np.int8),
                "step": np.asarray(observation["step"], dtype=np.int64)
                if batched
                else int(observation["step"]),
                "last_action": last_action if batched else int(last_action),
            }
        k, length = self.k, self.N
        target = np.asarray(observation["target"])
        step = np.asarray(observation["step"])
        pattern = np.asarray(observation["pattern"], dtype=np.float32)  # [..., N]
        index = step[..., None] + self._ahead  # [..., N]
        ahead = np.where(
            index < length,
            np.take_along_axis(pattern, np.minimum(index, length - 1), axis=-1),
            np.float32(-1.0),
        )  # [..., N]
        scaled = self._scaled(voltage)
        low, high = self.space.low[0], self.space.high[0]
        return np.concatenate(
            [
                np.clip(scaled, low, high).astype(np.float32),  # [..., k]
                _one_hot(target, k),  # [..., k]
                _one_hot(last_action, k + 1),  # [..., k+1]
                _one_hot(step, length + 1),  # [..., N+1]
                pattern,  # [..., N]
                ahead.astype(np.float32),  # [..., N]
            ],
            axis=-1,
        )


def _one_hot(index: np.ndarray, size: int) -> np.ndarray:
    return np.eye(size, dtype=np.float32)[index]  # [..., size]


def check_illegal_action(illegal_action: str) -> None:
    """Raise ValueError unless ``illegal_action`` is one of :data:`ILLEGAL_ACTIONS`."""
    if illegal_action not in ILLEGAL_ACTIONS:
        raise ValueError(f"illegal_action must be one of {ILLEGAL_ACTIONS}, got {illegal_action!r}")


def observation_for(env: Any, flatten: bool) -> SB3Observation:
    """The :class:`SB3Observation` of a (single or vector) spikectl environment."""
    return SB3Observation(
        env.n_observed,
        env.n_neurons,
        env.episode_length,
        env.params,
        env.extensions.stochastic_release,
        flatten,
    )
