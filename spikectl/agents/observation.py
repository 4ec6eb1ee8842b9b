"""The observation contract of the four networks, its checks and its conversion.

One step of the environment, as a dict:

- ``voltage``     float   membrane potentials in mV, one per neuron
- ``target``      int     index of the target neuron
- ``pattern``     0/1     the target spike pattern, length N
- ``step``        int     index t of the step about to be taken (0..N)
- ``last_action`` int     previous action, -1 = did nothing / episode start

Networks take the same keys as torch tensors with a leading ``[B, T]`` (sequence
forward) or ``[B]`` (step forward); docs/agents.md has the table and the checks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch

OBS_KEYS = ("voltage", "target", "pattern", "step", "last_action")
"""Keys every observation batch must hold (extra keys are ignored)."""

OPTIONAL_KEYS = ("position", "actions_in_flight")
"""Keys a network reads only when its sizes say so (``position``: float [n], each
neuron's position on the generator's line, read by the ``proximity`` input feature,
the neurons' indices where absent; ``actions_in_flight``: int [L], the actions chosen
but not landed yet under loop latency, read by the ``actions-in-flight`` feature)."""

_INDEX_KEYS = ("target", "step", "last_action")
"""The integer-valued keys of one value per observation (int64 once converted)."""
_INTEGER_KEYS = (*_INDEX_KEYS, "actions_in_flight")
"""Every integer-valued key (int64 once converted)."""


def check_observation(
    obs: Mapping[str, torch.Tensor],
    *,
    leading_dims: int,
    episode_length: int,
    n_neurons: int | None,
    where: str,
) -> tuple[tuple[int, ...], int]:
    """Validate an observation batch; return (leading shape, n).

    ``leading_dims`` is 2 for a sequence batch ``[B, T, ...]`` and 1 for a step
    batch ``[B, ...]``. ``n_neurons`` is the fixed n of the network, or None when
    the network accepts any n. Only cheap checks: keys, types, dtypes and shapes
    always; value ranges only for tensors on the CPU, where they cost no device
    synchronisation.
    """
    voltage_shape = "[B, T, n]" if leading_dims == 2 else "[B, n]"
    if not isinstance(obs, Mapping):
        raise TypeError(f"{where}: observation must be a dict of tensors, got {type(obs).__name__}")
    missing = [key for key in OBS_KEYS if key not in obs]
    if missing:
        raise ValueError(
            f"{where}: observation is missing keys {missing}; expected keys {list(OBS_KEYS)}"
        )
    for key in OBS_KEYS:
        if not isinstance(obs[key], torch.Tensor):
            raise TypeError(
                f"{where}: obs[{key!r}] must be a torch.Tensor, got {type(obs[key]).__name__} "
                "(convert with spikectl.agents.observation_batch or torch.as_tensor)"
            )

    voltage = obs["voltage"]
    if not voltage.is_floating_point():
        raise TypeError(f"{where}: obs['voltage'] must be floating point, got {voltage.dtype}")
    if voltage.dim() != leading_dims + 1:
        raise ValueError(
            f"{where}: obs['voltage'] must have shape {voltage_shape}, got {tuple(voltage.shape)}"
        )
    lead = tuple(voltage.shape[:leading_dims])
    n = int(voltage.shape[-1])
    if n < 1:
        raise ValueError(f"{where}: obs['voltage'] has no neurons (shape {tuple(voltage.shape)})")
    if n_neurons is not None and n != n_neurons:
        raise ValueError(
            f"{where}: this network is built for a fixed number of neurons: expected "
            f"n = {n_neurons}, got n = {n} (only the per-neuron networks DDRQN and TDRQN "
            "run on any n)"
        )
    for key in _INDEX_KEYS:
        value = obs[key]
        if value.is_floating_point() or value.is_complex() or value.dtype == torch.bool:
            raise TypeError(f"{where}: obs[{key!r}] must be an integer tensor, got {value.dtype}")
        if tuple(value.shape) != lead:
            raise ValueError(
                f"{where}: obs[{key!r}] must have shape {lead} (the leading dims of "
                f"obs['voltage']), got {tuple(value.shape)}"
            )
    pattern = obs["pattern"]
    if pattern.is_complex():
        raise TypeError(f"{where}: obs['pattern'] must be real (0/1), got {pattern.dtype}")
    if tuple(pattern.shape) != lead + (episode_length,):
        raise ValueError(
            f"{where}: obs['pattern'] must have shape {lead + (episode_length,)} (pattern "
            f"length = episode length {episode_length}), got {tuple(pattern.shape)}"
        )
    position = obs.get("position")
    if position is not None:
        if not isinstance(position, torch.Tensor) or position.is_complex():
            got = position.dtype if isinstance(position, torch.Tensor) else type(position).__name__
            raise TypeError(f"{where}: obs['position'] must be a real tensor, got {got}")
        if tuple(position.shape) != tuple(voltage.shape):
            raise ValueError(
                f"{where}: obs['position'] must have the shape of obs['voltage'] "
                f"{tuple(voltage.shape)} (one position per neuron), got {tuple(position.shape)}"
            )
    in_flight = obs.get("actions_in_flight")
    if in_flight is not None and (
        not isinstance(in_flight, torch.Tensor)
        or in_flight.is_floating_point() or in_flight.is_complex() or in_flight.dtype == torch.bool
        or tuple(in_flight.shape[:-1]) != lead or in_flight.dim() != leading_dims + 1
    ):  # fmt: skip
        got = tuple(in_flight.shape) if isinstance(in_flight, torch.Tensor) else in_flight
        raise ValueError(
            f"{where}: obs['actions_in_flight'] must be an integer tensor of shape "
            f"{lead + ('L',)} (the actions chosen and not landed yet), got {got}"
        )

    # Inside vmap (stacked seed groups) values cannot be read without leaving the
    # transform; shapes and dtypes are still checked, and the trainer's inputs come
    # from the environment and the replay buffer.
    if voltage.device.type == "cpu" and voltage.numel() > 0 and not _is_transformed(voltage):
        _check_range(obs["target"], 0, n - 1, "target", where)
        _check_range(obs["last_action"], -1, n - 1, "last_action", where)
        _check_range(obs["step"], 0, episode_length, "step", where)
        if in_flight is not None and in_flight.numel() > 0:
            _check_range(in_flight, -1, n - 1, "actions_in_flight", where)
        if position is not None and not bool(torch.isfinite(position).all()):
            raise ValueError(f"{where}: obs['position'] must be finite (one place per neuron)")
    return lead, n


def _is_transformed(tensor: torch.Tensor) -> bool:
    """Whether ``tensor`` is wrapped by a torch.func transform (vmap, grad)."""
    return torch._C._functorch.is_functorch_wrapped_tensor(tensor)


def _check_range(value: torch.Tensor, low: int, high: int, key: str, where: str) -> None:
    lo, hi = int(value.min()), int(value.max())
    if lo < low or hi > high:
        raise ValueError(f"{where}: obs[{key!r}] must lie in [{low}, {high}], got [{lo}, {hi}]")


def check_state(
    state: tuple[torch.Tensor, ...], expected: Sequence[tuple[int, ...]], where: str
) -> None:
    """Check that a hidden state is a tuple of tensors of the expected shapes."""
    if not isinstance(state, tuple) or len(state) != len(expected):
        raise TypeError(
            f"{where}: state must be a tuple of {len(expected)} tensors (from initial_state), "
            f"got {type(state).__name__}"
        )
    for i, (tensor, shape) in enumerate(zip(state, expected, strict=True)):
        if not isinstance(tensor, torch.Tensor) or tuple(tensor.shape) != tuple(shape):
            got = tuple(tensor.shape) if isinstance(tensor, torch.Tensor) else type(tensor).__name__
            raise ValueError(f"{where}: state[{i}] must have shape {tuple(shape)}, got {got}")


def observation_batch(
    observations: Mapping[str, object] | Sequence[Mapping[str, object]],
    device: torch.device | str | None = None,
) -> dict[str, torch.Tensor]:
    """Environment observations (NumPy arrays / ints) → a step batch [B] of tensors.

    Takes either a sequence of single-environment observations (stacked along a
    new batch dimension) or one already batched dict, as a vector environment
    returns it. The result is what ``network.step`` takes: voltage float32 [B, n],
    pattern float32 [B, N], and target / step / last_action int64 [B]; ``position``
    float32 [B, n] where the observations hold it.
    """
    if isinstance(observations, Mapping):
        missing = [key for key in OBS_KEYS if key not in observations]
        if missing:
            raise ValueError(f"observation_batch: the batch lacks keys {missing}")
        keys = OBS_KEYS + tuple(key for key in OPTIONAL_KEYS if key in observations)
        arrays = {key: np.asarray(observations[key]) for key in keys}
    else:
        if len(observations) == 0:
            raise ValueError("observation_batch: need at least one observation")
        try:
            keys = OBS_KEYS + tuple(key for key in OPTIONAL_KEYS if key in observations[0])
            arrays = {key: np.stack([np.asarray(o[key]) for o in observations]) for key in keys}
        except KeyError as error:
            raise ValueError(f"observation_batch: an observation lacks key {error}") from None
    out: dict[str, torch.Tensor] = {}
    for key, array in arrays.items():
        dtype = np.int64 if key in _INTEGER_KEYS else np.float32
        out[key] = torch.as_tensor(array.astype(dtype, copy=False), device=device)
    return out


def long_indices(obs: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The observation with target / step / last_action as int64 (no copy if they are)."""
    out = {key: obs[key] for key in OBS_KEYS + OPTIONAL_KEYS if key in obs}
    for key in _INTEGER_KEYS:
        if key in out:
            out[key] = out[key].long()
    return out
