"""A trained per-neuron Q-network as a compiled policy: the per-step recurrent forward in
one Numba function, loaded from a file that needs neither PyTorch nor the trainer
(issue 24; docs/realtime.md).

``export_policy(network, path)`` writes a TDRQN or DDRQN (:func:`make_agent`, trained or
not) to one ``.npz`` file: a JSON header (format name and version, the architecture, the
sizes and options the forward needs) and every weight as a float32 array under its
state-dict name. ``CompiledPolicy.load(path)`` reads it back, checks it, and acts with
the interface the planners have: ``reset()`` and ``act(observation, info) -> int``, the
masked greedy action of one environment, carrying the recurrent state itself.

Importing this module imports NumPy and Numba only; :func:`export_policy` imports
PyTorch inside, since it reads a PyTorch network. The forward is the networks' own
(docs/agents.md): per-neuron features → LSTM cell → transformer encoder across neurons
(TDRQN) or a per-neuron FF layer (DDRQN) → per-neuron context → Q head, with both
do-nothing forms and both target-indicator options; ``test_compiled_policy.py`` checks
that it picks the PyTorch network's actions. Shapes in comments: n neurons, N episode
length, F per-neuron input features, H LSTM width, W attention width, M mixing output
width, E / P target / pattern code widths, U = M + E + P head input width.
"""

from __future__ import annotations

import io
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spikectl.agents.policy_file import (
    FORMAT_VERSION,
    HEADER_KEY,
    PolicyFileError,
    PolicySpec,
    _mismatch,
    _policy_bytes,
    export_policy,
)
from spikectl.agents.policy_header import check_policy_checksum, header_differences, parse_header
from spikectl.agents.policy_kernel import _decide, _layout
from spikectl.envs.controller import ControllerInputError, check_controller_input
from spikectl.envs.sensing import with_sensed_potentials
from spikectl.file_kinds import FileKind, refuse_other_kinds
from spikectl.files import NotARegularFileError, npz_size_problem, open_regular_file


class CompiledPolicy:
    """A trained TDRQN or DDRQN as a NumPy/Numba policy for one environment.

    ``reset()`` forgets the episode (``act`` at step 0 also does); ``act(observation,
    info)`` returns the legal action of highest Q-value (-1 = do nothing, j = stimulate
    neuron j), as ``GreedyController`` picks it from the PyTorch network, and advances the
    recurrent state. ``last_q`` holds that decision's Q-values [n + 1] (action + 1
    order). Runs on any n, like the network. Build one with :meth:`load` (a file from
    :func:`export_policy`) or :meth:`from_network`.
    """

    def __init__(self, spec: PolicySpec, weights: Mapping[str, np.ndarray], where: str) -> None:
        shapes = {name: tuple(array.shape) for name, array in weights.items()}
        expected = spec.weight_shapes()
        if shapes != expected:
            differences = header_differences(spec, shapes)
            if differences:
                raise PolicyFileError(
                    f"{where}: its header does not match its weights: {'; '.join(differences)}"
                )
            raise PolicyFileError(f"{where}: the weights {_mismatch(expected, shapes)}")
        self.spec = spec
        self._params, self._rows, self._ints, self._floats = _layout(spec, weights)
        self._h: np.ndarray | None = None
        self._c: np.ndarray | None = None
        self._q = np.zeros(0, dtype=np.float32)

    @classmethod
    def load(cls, path: str | Path, warm_up: bool = True) -> CompiledPolicy:
        """Read a file written by :func:`export_policy`, checked: an unreadable file, a
        foreign one, another format version, an unsupported architecture or weights that
        do not match the header raise :class:`PolicyFileError` naming the problem.

        ``warm_up`` makes one decision on a dummy observation so the kernel is compiled
        (or loaded from Numba's cache) here, not in the first real decision.
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"compiled policy file not found: {path}")
        if path.is_dir():
            raise PolicyFileError(f"{path} is a folder, not a compiled policy file")
        refuse_other_kinds(path, (FileKind.POLICY,), "a compiled policy is an .npz written by "
                           "export_policy", PolicyFileError)  # fmt: skip
        try:
            # One guarded open: a FIFO or a device would block or never end.
            with open_regular_file(path) as handle:
                return cls._from_npz(handle, str(path), warm_up)
        except NotARegularFileError as error:
            raise PolicyFileError(
                f"{path} is not a compiled policy file: {error.strerror}"
            ) from None

    @classmethod
    def from_network(cls, network: Any, warm_up: bool = True) -> CompiledPolicy:
        """The compiled policy of a PyTorch TDRQN or DDRQN, through the very bytes
        :func:`export_policy` would write (nothing is written)."""
        return cls._from_npz(io.BytesIO(_policy_bytes(network)), "the exported network", warm_up)

    @classmethod
    def _from_npz(cls, source: Any, where: str, warm_up: bool) -> CompiledPolicy:
        try:
            problem = npz_size_problem(source)  # before any array is allocated
            if problem is not None:
                separator = " " if problem.startswith("is ") else ": "
                raise PolicyFileError(f"{where}{separator}{problem}")
            source.seek(0)
            with np.load(source, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except PolicyFileError:
            raise
        except (zipfile.BadZipFile, OSError, ValueError, EOFError, zlib.error) as error:
            problem = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise PolicyFileError(
                f"{where} is not a readable compiled policy: {problem}"
            ) from error
        if HEADER_KEY not in arrays:
            raise PolicyFileError(f"{where} is not a compiled policy (no {HEADER_KEY!r} entry)")
        raw_header = arrays.pop(HEADER_KEY)
        spec = parse_header(where, raw_header)
        bad = sorted(name for name, array in arrays.items() if array.dtype != np.float32)
        if bad:
            raise PolicyFileError(f"{where}: weights {bad} are not float32")
        bad = sorted(name for name, array in arrays.items() if not np.isfinite(array).all())
        if bad:
            raise PolicyFileError(f"{where}: weights {bad} hold NaN or infinite values")
        policy = cls(spec, arrays, where)
        check_policy_checksum(where, raw_header, spec, arrays)
        if warm_up:
            policy.warm_up()
        return policy

    def warm_up(self) -> None:
        """One decision on a dummy observation (compiles the kernel), then ``reset``."""
        n, N = max(2, self.spec.n_neurons), self.spec.episode_length
        observation = dict(
            voltage=np.full(n, self.spec.v_rest_mV, dtype=np.float32),
            target=0, pattern=np.zeros(N, dtype=np.int8), step=0, last_action=-1,
        )  # fmt: skip
        self.act(observation, {"action_mask": np.ones(n + 1, dtype=bool)})
        self.reset()

    def reset(self) -> None:
        """Forget the episode: the next ``act`` starts from the zero state."""
        self._h = self._c = None

    @property
    def last_q(self) -> np.ndarray:
        """The Q-values of the last decision [n + 1] (a copy; empty before any)."""
        return self._q.copy()

    def _positions(self, observation: Mapping[str, Any], n: int) -> np.ndarray:
        """[n] float32: ``observation["position"]`` (each neuron's position on the line)
        where it is given, else the neurons' indices (as the PyTorch network reads them),
        made once an episode."""
        position = observation.get("position")
        if position is None:
            return self._index_positions
        position = np.ascontiguousarray(position, dtype=np.float32)
        if position.shape != (n,) or not np.isfinite(position).all():
            raise ValueError(
                f"CompiledPolicy.act: observation['position'] must hold {n} finite positions "
                f"(one per neuron), got shape {position.shape}"
            )
        return position

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> int:
        """The legal action of highest Q-value for this observation (-1 = do nothing).

        ``observation`` is the single environment's dict (voltage [n], target, pattern
        [N], step, last_action), ``info["action_mask"]`` bool [n + 1]. Step 0 starts a
        new episode (zero state); a step other than 0 continues the current one. Under
        spikes-only sensing (``spikes`` [n] in place of ``voltage``) each spike is read
        as a potential at threshold, as the PyTorch network reads it.
        """
        check_controller_input(observation, info, "CompiledPolicy")
        spec = self.spec
        observation = with_sensed_potentials(observation, spec.v_rest_mV, spec.v_threshold_mV)
        voltage = np.ascontiguousarray(observation["voltage"], dtype=np.float32)
        pattern = np.ascontiguousarray(observation["pattern"], dtype=np.int8)
        mask = np.ascontiguousarray(info["action_mask"], dtype=np.bool_)
        target, step = int(observation["target"]), int(observation["step"])
        last_action = int(observation["last_action"])
        n, N = voltage.shape[0], self.spec.episode_length
        if voltage.ndim != 1 or pattern.shape != (N,) or mask.shape != (n + 1,):
            raise ValueError(
                f"CompiledPolicy.act: expected voltage [n], pattern [{N}] and action_mask "
                f"[n + 1]; got {voltage.shape}, {pattern.shape} and {mask.shape}"
            )
        if not (0 <= target < n and 0 <= step < N and -1 <= last_action < n):
            raise ValueError(
                f"CompiledPolicy.act: target {target}, step {step} or last_action "
                f"{last_action} out of range for n = {n}, N = {N} (the episode has {N} steps)"
            )
        if step == 0 or self._h is None:
            if step != 0:
                raise ValueError(
                    "CompiledPolicy.act: the policy must see the episode from step 0 "
                    f"(got step {step} after reset)"
                )
            self._h = np.zeros((n, self.spec.lstm_hidden), dtype=np.float32)  # [n, H]
            self._c = np.zeros((n, self.spec.lstm_hidden), dtype=np.float32)  # [n, H]
            self._q = np.zeros(n + 1, dtype=np.float32)
            self._index_positions = np.arange(n, dtype=np.float32)  # [n]
        elif self._h.shape[0] != n:
            raise ValueError(
                f"CompiledPolicy.act: the episode started with n = {self._h.shape[0]}, "
                f"this observation has n = {n}"
            )
        best = _decide(
            self._params, self._rows, self._ints, self._floats, voltage,
            self._positions(observation, n), target, pattern, step, last_action, self._h,
            self._c, mask, self._q,
        )  # fmt: skip
        if best < 0:
            raise ControllerInputError("CompiledPolicy.act: the action mask allows no action")
        return best - 1


__all__ = ["FORMAT_VERSION", "CompiledPolicy", "PolicyFileError", "export_policy"]
