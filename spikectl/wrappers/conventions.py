"""The ecosystem's conventions, in one place: what every flat id and adapter writes.

Generic RL libraries (CleanRL, TorchRL, RLlib, Stable-Baselines3) assume a zero-based
``Discrete`` action space, a float32 ``Box`` observation with finite bounds, an int8
action mask (what ``Discrete.sample(mask=...)`` takes) and that any action of the space
may be sent. The paper's environment (docs/environment.md) writes actions -1..n-1, a
``Dict`` observation with an unbounded voltage, and raises on the target neuron. This
module is the translation, shared by the flat environments
(:mod:`spikectl.wrappers.flat_env`, :mod:`spikectl.wrappers.flat_vector_env`) and the SB3
adapters (:mod:`spikectl.wrappers.sb3`, :mod:`spikectl.wrappers.sb3_vec_adapter`):

- actions: zero-based a is the paper's a - 1 (0 does nothing, a >= 1 stimulates
  neuron a - 1), so mask column a is the paper's ``info["action_mask"]`` column a;
- the action mask: int8, 1 = legal;
- an illegal action (the target neuron): does nothing and is reported
  (``"do_nothing"``, the default) or raises ``ValueError`` (``"raise"``);
- observations: one float32 vector with finite bounds (:class:`FlatObservation`), or the
  paper's ``Dict`` with zero-based ``last_action`` and a clipped voltage.

Needs no other library.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from gymnasium import spaces

from spikectl.envs.env_arguments import TARGET_RULE, bad_actions_message
from spikectl.envs.latency import IN_FLIGHT_KEY
from spikectl.envs.sensing import RECORDED_KEY, SPIKES_KEY, Sensing, sensed_key
from spikectl.neuron.params import NEVER_RELEASES, NeuronParams

DO_NOTHING = 0
"""The zero-based action that stimulates no neuron (the base environment's -1)."""
ILLEGAL_ACTIONS = ("do_nothing", "raise")
"""What an illegal action (stimulating the target) does: nothing, or raise ValueError."""
MASK_DTYPE = np.int8
"""dtype of every ``info["action_mask"]``: Gymnasium's ``Discrete.sample(mask=...)`` takes int8."""


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


class FlatObservation:
    """The flat observation space and the map from the paper's observation to it.

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
    | next L (k + 1) | with loop latency L > 0 only: the actions in flight,      |
    |                | oldest first, each one-hot over 0..k                      |
    | next k         | with a recorded subset only: 1 for each recorded neuron   |

    With spikes-only sensing (``spikes_only``, an extension) the first k entries are the
    spikes, 1 for a neuron that spiked at the last step, else 0 (where the scaled voltage
    would read >= 1 and < 1), and the ``Dict`` has ``spikes`` (int8) in place of
    ``voltage``; the size and every other entry are as above. ``sensing`` is a
    :class:`~spikectl.envs.sensing.Sensing` (a bool: spikes only or not); with its
    ``recorded`` (``recorded_neurons``, an extension) an unrecorded neuron's spike columns
    read 0, the vector ends with k entries more (the ``recorded`` mask) and the ``Dict``
    has int8 ``recorded``.

    The pattern ahead repeats what pattern and step say, aligned with the current step,
    so that a policy without memory or attention can read the next wanted spikes.
    Every entry but the voltage lies in [0, 1] (the pattern ahead in [-1, 1]). With
    ``latency_steps`` L > 0 (an extension) the ``Dict`` has ``actions_in_flight`` too
    (zero-based, as ``last_action``) and the vector L (k + 1) more entries; with L = 0
    both are as they were.
    """

    def __init__(
        self,
        n_observed: int,
        n_neurons: int,
        episode_length: int,
        params: NeuronParams,
        stochastic_release: bool = False,
        flatten: bool = True,
        latency_steps: int = 0,
        sensing: Sensing | bool = False,
    ) -> None:
        self.k = k = n_observed
        self.N = length = episode_length
        self.flatten = flatten
        self.latency_steps = latency_steps
        sensing = sensing if isinstance(sensing, Sensing) else Sensing(bool(sensing))
        self.spikes_only = spikes_only = sensing.spikes_only
        self.recorded = sensing.recorded
        self.v_rest_mV, self.v_threshold_mV = params.v_rest_mV, params.v_threshold_mV
        low, high = _float32_outward(*voltage_bounds_mV(params, n_neurons, stochastic_release))
        self.voltage_low_mV, self.voltage_high_mV = low, high
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
            if latency_steps:
                self.space[IN_FLIGHT_KEY] = spaces.MultiDiscrete(np.full(latency_steps, k + 1))
            if spikes_only:
                del self.space.spaces["voltage"]
                self.space[SPIKES_KEY] = spaces.MultiBinary(k)
            if self.recorded:
                self.space[RECORDED_KEY] = spaces.MultiBinary(k)
            return
        # The paper's layout, then the actions in flight (none without latency), then the
        # recorded neurons (none without a recorded subset).
        self.in_flight_column = 3 * k + 3 * length + 2
        self.recorded_column = self.in_flight_column + latency_steps * (k + 1)
        self.size = size = self.recorded_column + (k if self.recorded else 0)
        lows = np.zeros(size, dtype=np.float32)
        highs = np.ones(size, dtype=np.float32)
        lows[:k], highs[:k] = _float32_outward(self._scaled(low), self._scaled(high))
        if spikes_only:  # the spikes' columns
            lows[:k], highs[:k] = 0.0, 1.0
        lows[self.in_flight_column - length : self.in_flight_column] = -1.0
        self.space = spaces.Box(lows, highs, (size,), np.float32)
        self._constants = np.array(
            [low, high, self.v_rest_mV, 1.0 / (self.v_threshold_mV - self.v_rest_mV),
             lows[0], highs[0]],
        )  # fmt: skip

    def _scaled(self, voltage_mV: Any) -> Any:
        return (voltage_mV - self.v_rest_mV) / (self.v_threshold_mV - self.v_rest_mV)

    def __call__(self, observation: dict[str, Any]) -> np.ndarray | dict[str, Any]:
        """The observation (or batch) of the base environment in this space."""
        if self.spikes_only:
            voltage = np.asarray(observation[SPIKES_KEY], dtype=np.int8)
        else:
            voltage = np.clip(
                np.asarray(observation["voltage"], dtype=np.float32),
                self.voltage_low_mV,
                self.voltage_high_mV,
            )
        last_action = from_env_action(np.asarray(observation["last_action"], dtype=np.int64))
        if not self.flatten:
            batched = voltage.ndim == 2
            converted = {
                sensed_key(self.spikes_only): voltage,
                "target": np.asarray(observation["target"], dtype=np.int64)
                if batched
                else int(observation["target"]),
                "pattern": np.asarray(observation["pattern"], dtype=np.int8),
                "step": np.asarray(observation["step"], dtype=np.int64)
                if batched
                else int(observation["step"]),
                "last_action": last_action if batched else int(last_action),
            }
            if self.latency_steps:
                converted[IN_FLIGHT_KEY] = self._in_flight(observation)
            if self.recorded:
                converted[RECORDED_KEY] = np.asarray(observation[RECORDED_KEY], dtype=np.int8)
            return converted
        return self._flat(voltage, observation, last_action)

    def _in_flight(self, observation: dict[str, Any]) -> np.ndarray:
        """The observation's actions in flight, zero-based."""
        return from_env_action(np.asarray(observation[IN_FLIGHT_KEY], dtype=np.int64))

    def _flat(
        self, voltage: np.ndarray, observation: dict[str, Any], last_action: np.ndarray
    ) -> np.ndarray:
        single = voltage.ndim == 1
        spikes = voltage.reshape(-1, self.k) if self.spikes_only else None
        out = self.write(
            np.zeros(spikes.shape) if self.spikes_only else voltage.reshape(-1, self.k),
            np.asarray(observation["target"], dtype=np.int64).reshape(-1),
            last_action.reshape(-1),
            np.asarray(observation["step"], dtype=np.int64).reshape(-1),
            np.asarray(observation["pattern"], dtype=np.int8).reshape(-1, self.N),
            self._in_flight(observation).reshape(-1, self.latency_steps)
            if self.latency_steps
            else None,
            spikes,
            np.asarray(observation[RECORDED_KEY]).reshape(-1, self.k) if self.recorded else None,
        )
        return out[0] if single else out

    def write(
        self,
        voltage_mV: np.ndarray,
        target: np.ndarray,
        last_action: np.ndarray,
        step: np.ndarray,
        pattern: np.ndarray,
        in_flight: np.ndarray | None = None,
        spikes: np.ndarray | None = None,
        recorded: np.ndarray | None = None,
    ) -> np.ndarray:
        """The flat observations [B, size] of a batch given as arrays: voltage [B, k] in mV,
        target, zero-based last action and step int64 [B], pattern int8 [B, N]; with
        latency, the zero-based actions in flight int64 [B, L]; with spikes-only sensing,
        the spikes [B, k] (0 or 1), written over the voltage's columns; with a recorded
        subset, the recorded mask [B, k] (0 or 1)."""
        out = np.empty((voltage_mV.shape[0], self.size), dtype=np.float32)
        _write_flat(voltage_mV, target, last_action, step, pattern, self._constants, out)
        if self.spikes_only:
            out[:, : self.k] = spikes
        if self.latency_steps:
            # The compiled writer fills every row to its end (the pattern ahead's -1s run
            # into these columns): the one-hot blocks are written over them.
            blocks = out[:, self.in_flight_column :]
            blocks[:] = 0.0
            offsets = np.arange(self.latency_steps) * (self.k + 1)
            rows = np.arange(out.shape[0])[:, None]
            blocks[rows, offsets + in_flight] = 1.0
        if self.recorded:  # after the pattern ahead's -1s and the blocks, as they run here
            out[:, self.recorded_column :] = recorded
        return out


@numba.njit(cache=True, nogil=True)
def _write_flat(voltage_mV, target, last_action, step, pattern, constants, out):
    """Every row of ``out`` in the layout of :class:`FlatObservation`, in one pass.

    ``constants``: float64 [6], (low_mV, high_mV, V_rest, 1 / (V_th - V_rest), low, high):
    few arguments, because the batched environment calls this at every step and numba's
    dispatch cost grows with them.
    """
    rows, k = voltage_mV.shape
    length = pattern.shape[1]
    last_action_column = 2 * k
    step_column = 3 * k + 1
    pattern_column = 3 * k + length + 2
    ahead_column = pattern_column + length
    low_mV, high_mV = np.float32(constants[0]), np.float32(constants[1])
    v_rest_mV, scale, low, high = constants[2], constants[3], constants[4], constants[5]
    for b in range(rows):
        row = out[b]  # a contiguous view: plain loops that the compiler vectorises
        for j in range(k):
            # Clipped in float32 mV first, as the Dict observation is, then scaled.
            v = min(max(np.float32(voltage_mV[b, j]), low_mV), high_mV)
            row[j] = min(max((v - v_rest_mV) * scale, low), high)
        row[k:pattern_column] = 0.0
        row[k + target[b]] = 1.0
        row[last_action_column + last_action[b]] = 1.0
        t = step[b]
        row[step_column + t] = 1.0
        patterns = pattern[b]
        row[pattern_column:ahead_column] = patterns
        row[ahead_column : ahead_column + length - t] = patterns[t:]
        row[ahead_column + length - t :] = -1.0


SB3Observation = FlatObservation
"""The name under which the SB3 adapters first exported :class:`FlatObservation`."""


def legal_or_nothing(
    actions: np.ndarray, legal: np.ndarray, illegal_action: str
) -> tuple[np.ndarray, np.ndarray]:
    """Apply the illegal-action rule to zero-based ``actions`` [B] under masks ``legal`` [B, k+1].

    Returns (the actions with every illegal one replaced by :data:`DO_NOTHING`, bool [B]
    marking them); with ``illegal_action="raise"`` illegal actions raise one ValueError
    naming how many and the first environments that sent one. (The flat batched
    environment applies the same rule in one compiled pass.)
    """
    row_offsets = np.arange(0, legal.size, legal.shape[1])
    illegal = legal.reshape(-1).take(row_offsets + actions) == 0
    if not illegal.any():
        return actions, illegal
    if illegal_action == "raise":
        raise ValueError(bad_actions_message(
            actions, illegal, "are illegal", f'{TARGET_RULE} (see info["action_mask"]; '
            'illegal_action="do_nothing" makes it do nothing)',
        ))  # fmt: skip
    return np.where(illegal, DO_NOTHING, actions), illegal


def check_illegal_action(illegal_action: str) -> None:
    """Raise ValueError unless ``illegal_action`` is one of :data:`ILLEGAL_ACTIONS`."""
    if illegal_action not in ILLEGAL_ACTIONS:
        raise ValueError(f"illegal_action must be one of {ILLEGAL_ACTIONS}, got {illegal_action!r}")


def observation_for(env: Any, flatten: bool) -> FlatObservation:
    """The :class:`FlatObservation` of a (single or vector) spikectl environment."""
    return FlatObservation(
        env.n_observed,
        env.n_neurons,
        env.episode_length,
        env.params,
        env.extensions.stochastic_release,
        flatten,
        env.extensions.latency_steps,
        Sensing.of(env.extensions),
    )
