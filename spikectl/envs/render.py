"""Episode rasters as text or as an RGB image, from plain arrays.

The functions here know nothing of Gymnasium: the environments, the vector
environment, the CLI and the figures all pass them the same arrays:

- ``pattern``: [N] the target pattern (0/1), drawn in full, future steps included;
- ``target_spikes``: [>= step] the target's spikes (normally ``spikes[:, target]``);
- ``actions``: [>= step] actions taken, -1 = do nothing;
- ``spikes``: [>= step, n] spikes of every neuron;
- ``target``: the target neuron;
- ``step``: how many steps have been taken; later entries of the arrays are ignored.

The target row classifies every step: a *hit* (wanted spike, fired), a *miss*
(wanted spike, silent), an *extra* spike (fired, not wanted) or a correct silence.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded

DO_NOTHING = -1

# Text raster characters.
ANSI_PATTERN_SPIKE, ANSI_SILENT = "|", "."
ANSI_HIT, ANSI_MISS, ANSI_EXTRA = "|", "o", "x"
ANSI_SPIKE, ANSI_STIMULATED = "|", "*"
ANSI_FUTURE = " "
_ACTION_CHARACTERS = "0123456789abcdefghijklmnopqrstuvwxyz"
ANSI_LABEL_WIDTH = 12

# Image layout, in pixels.
CELL_WIDTH_PX = 6
CELL_HEIGHT_PX = 10
CELL_GAP_PX = 1
GROUP_GAP_PX = 6
"""Extra space between the pattern/target rows and the stimulus/neuron rows."""
MARGIN_PX = 4
FRAME_MULTIPLE_PX = 16
"""Frames are padded to a multiple of this, which video encoders expect."""

# Rows of the image: the pattern, the target's spikes, the stimulus, then every
# other neuron in increasing index order.
ROW_PATTERN, ROW_TARGET, ROW_STIMULUS, FIRST_NEURON_ROW = 0, 1, 2, 3

# RGB colours.
BACKGROUND = (24, 24, 24)
GRID = (64, 64, 64)
"""Gap before every 10th step."""
FUTURE = (40, 40, 40)
SILENT = (80, 80, 80)
PATTERN_SPIKE = (240, 240, 240)
HIT = (40, 200, 80)
MISS = (220, 50, 50)
EXTRA = (240, 150, 30)
SPIKE = (240, 240, 240)
STIMULUS = (70, 130, 240)
STIMULATED_SILENT = (40, 70, 140)
"""A stimulated neuron that did not spike (it was refractory)."""

_PALETTE = np.array(
    [FUTURE, SILENT, PATTERN_SPIKE, HIT, MISS, EXTRA, SPIKE, STIMULUS, STIMULATED_SILENT],
    dtype=np.uint8,
)
(_FUTURE, _SILENT, _PATTERN_SPIKE, _HIT, _MISS, _EXTRA, _SPIKE, _STIMULUS,
 _STIMULATED_SILENT) = range(len(_PALETTE))  # fmt: skip


class _Episode(NamedTuple):
    """The checked arrays of :func:`render`, cut to the ``step`` steps taken."""

    pattern: np.ndarray  # [N] bool
    target_spikes: np.ndarray  # [step] bool
    actions: np.ndarray  # [step]
    spikes: np.ndarray  # [step, n] bool
    n_neurons: int
    target: int
    step: int


def can_render(render_mode: str | None, started: bool, maker: str) -> bool:
    """Whether an environment's ``render()`` draws: False, with Gymnasium's warning,
    without a render mode (``maker`` names the call that takes one); ``ResetNeeded``
    before the first reset (``started`` False)."""
    if render_mode is None:
        gym.logger.warn("render() called without a render_mode; pass render_mode='ansi' or "
                        f"'rgb_array' to the constructor (or to {maker})")  # fmt: skip
        return False
    if not started:
        raise ResetNeeded("call reset() before render()")
    return True


def render(
    render_mode: str,
    pattern: np.ndarray,
    target_spikes: np.ndarray,
    actions: np.ndarray,
    spikes: np.ndarray,
    target: int,
    step: int,
) -> str | np.ndarray:
    """The episode so far as text (``"ansi"``, :func:`_draw_ansi`) or as an RGB image
    (``"rgb_array"``, :func:`_draw_rgb`); the arrays are described above."""
    pattern = np.asarray(pattern).astype(bool)
    episode_length = pattern.shape[0]
    spikes = np.asarray(spikes, dtype=bool)
    if spikes.ndim != 2:
        raise ValueError(f"spikes must be [steps, n_neurons], got shape {spikes.shape}")
    n_neurons = spikes.shape[1]
    if not 0 <= target < n_neurons:
        raise ValueError(f"target {target} is not a neuron index in 0..{n_neurons - 1}")
    if not 0 <= step <= episode_length:
        raise ValueError(f"step {step} is not in 0..{episode_length}")
    target_spikes = np.asarray(target_spikes, dtype=bool)[:step]
    actions = np.asarray(actions)[:step]
    spikes = spikes[:step]
    if target_spikes.shape[0] < step or actions.shape[0] < step or spikes.shape[0] < step:
        raise ValueError(f"target_spikes, actions and spikes must hold at least {step} steps")
    draw = _draw_ansi if render_mode == "ansi" else _draw_rgb
    return draw(_Episode(pattern, target_spikes, actions, spikes, n_neurons, target, step))


# Each mode as a function of the six arrays alone.
render_ansi = functools.partial(render, "ansi")
render_rgb = functools.partial(render, "rgb_array")


def render_batch(
    render_mode: str,
    patterns: np.ndarray,
    actions: np.ndarray,
    spikes: np.ndarray,
    targets: np.ndarray,
    steps: np.ndarray,
) -> tuple[str, ...] | tuple[np.ndarray, ...]:
    """One raster per environment of a batch (:func:`render` of each): ``patterns``
    [B, N], ``actions`` [B, N], ``spikes`` [B, N, n], ``targets`` [B], ``steps`` [B]."""
    return tuple(
        render(
            render_mode,
            patterns[i],
            spikes[i, :, targets[i]],
            actions[i],
            spikes[i],
            int(targets[i]),
            int(steps[i]),
        )  # fmt: skip
        for i in range(len(patterns))
    )


def _target_codes(pattern: np.ndarray, target_spikes: np.ndarray) -> np.ndarray:
    """Per-step class of the target: 0 silent as wanted, 1 hit, 2 miss, 3 extra spike."""
    wanted = pattern[: target_spikes.shape[0]]
    return np.select(
        [wanted & target_spikes, wanted & ~target_spikes, ~wanted & target_spikes], [1, 2, 3], 0
    )


def _other_neurons(n_neurons: int, target: int) -> np.ndarray:
    return np.array([j for j in range(n_neurons) if j != target], dtype=np.int64)


def _draw_ansi(episode: _Episode) -> str:
    """A text raster of an episode so far: one column per step.

    Rows: ``pattern`` (``|`` wanted spike, ``.`` silence), the target (``|`` hit,
    ``o`` missed spike, ``x`` unwanted spike, ``.`` correct silence), ``stimulus``
    (the stimulated neuron's index as a base-36 digit, ``*`` for networks of more
    than 36 neurons, ``.`` do nothing), then each other neuron (``|`` spike,
    ``*`` stimulated, ``.`` silent). Steps not taken yet are blank except in the
    pattern row.
    """
    pattern, target_spikes, actions, spikes, n_neurons, target, step = episode
    episode_length = pattern.shape[0]
    codes = _target_codes(pattern, target_spikes)
    wanted_so_far = int(pattern[:step].sum())
    hits = int((codes == 1).sum())
    kept_silences = int((codes == 0).sum())

    def row(label: str, cells: str) -> str:
        return f"{label:<{ANSI_LABEL_WIDTH}}{cells.ljust(episode_length, ANSI_FUTURE)}".rstrip()

    columns = range(episode_length)
    lines = [
        f"step {step}/{episode_length}  target n{target}  hits {hits}/{wanted_so_far}  "
        f"correct silences {kept_silences}/{step - wanted_so_far}",
        row("", "".join(str(c // 10 % 10) if c % 10 == 0 else " " for c in columns)),
        row("", "".join(str(c % 10) for c in columns)),
        row("pattern", "".join(ANSI_PATTERN_SPIKE if p else ANSI_SILENT for p in pattern)),
        row(
            f"n{target} target",
            "".join((ANSI_SILENT, ANSI_HIT, ANSI_MISS, ANSI_EXTRA)[c] for c in codes),
        ),
    ]
    symbols = _ACTION_CHARACTERS if n_neurons <= len(_ACTION_CHARACTERS) else None
    stimulus = "".join(
        ANSI_SILENT if a == DO_NOTHING else (symbols[a] if symbols else ANSI_STIMULATED)
        for a in actions
    )
    lines.append(row("stimulus", stimulus))
    for neuron in _other_neurons(n_neurons, target):
        cells = np.where(spikes[:, neuron], ANSI_SPIKE, ANSI_SILENT)
        cells[actions == neuron] = ANSI_STIMULATED
        lines.append(row(f"n{neuron}", "".join(cells)))
    lines.append(
        f"legend: target {ANSI_HIT} hit, {ANSI_MISS} missed spike, {ANSI_EXTRA} unwanted spike; "
        f"neurons {ANSI_SPIKE} spike, {ANSI_STIMULATED} stimulated"
    )
    return "\n".join(lines) + "\n"


def _row_tops(n_rows: int) -> np.ndarray:
    tops = MARGIN_PX + np.arange(n_rows) * (CELL_HEIGHT_PX + CELL_GAP_PX)
    return tops + np.where(np.arange(n_rows) >= ROW_STIMULUS, GROUP_GAP_PX, 0)


def _column_lefts(episode_length: int) -> np.ndarray:
    return MARGIN_PX + np.arange(episode_length) * (CELL_WIDTH_PX + CELL_GAP_PX)


def cell_box(row: int, step: int) -> tuple[slice, slice]:
    """Pixel rows and columns of the cell of image row ``row`` at ``step``.

    Image rows are ``ROW_PATTERN``, ``ROW_TARGET``, ``ROW_STIMULUS``, then
    ``FIRST_NEURON_ROW + k`` for the k-th non-target neuron in index order.
    """
    top = int(_row_tops(row + 1)[row])
    left = int(_column_lefts(step + 1)[step])
    return slice(top, top + CELL_HEIGHT_PX), slice(left, left + CELL_WIDTH_PX)


def _draw_rgb(episode: _Episode) -> np.ndarray:
    """An episode raster as a uint8 [H, W, 3] image, drawn with NumPy only.

    Rows as in :func:`_draw_ansi`, located by :func:`cell_box`: the pattern
    (white = wanted spike), the target (green ``HIT``, red ``MISS``, orange
    ``EXTRA`` spike, grey correct silence), the stimulus row (blue where a neuron
    was stimulated), and one row per other neuron (white spike, blue stimulated,
    dark blue stimulated while refractory). Columns are steps, with a lighter gap
    every 10 steps; steps not taken yet are dark.
    """
    pattern, target_spikes, actions, spikes, n_neurons, target, step = episode
    episode_length = pattern.shape[0]
    others = _other_neurons(n_neurons, target)
    n_rows = FIRST_NEURON_ROW + others.size
    codes = np.full((n_rows, episode_length), _FUTURE, dtype=np.int64)
    codes[ROW_PATTERN] = np.where(pattern, _PATTERN_SPIKE, _SILENT)
    codes[ROW_TARGET, :step] = np.array([_SILENT, _HIT, _MISS, _EXTRA])[
        _target_codes(pattern, target_spikes)
    ]
    codes[ROW_STIMULUS, :step] = np.where(actions != DO_NOTHING, _STIMULUS, _SILENT)
    other_spikes = spikes[:, others].T  # [n - 1, step]
    stimulated = actions[None, :] == others[:, None]
    neuron_codes = np.where(other_spikes, _SPIKE, _SILENT)
    neuron_codes[stimulated] = np.where(other_spikes[stimulated], _STIMULUS, _STIMULATED_SILENT)
    codes[FIRST_NEURON_ROW:, :step] = neuron_codes

    tops, lefts = _row_tops(n_rows), _column_lefts(episode_length)
    height = _round_up(int(tops[-1]) + CELL_HEIGHT_PX + MARGIN_PX, FRAME_MULTIPLE_PX)
    width = _round_up(int(lefts[-1]) + CELL_WIDTH_PX + MARGIN_PX, FRAME_MULTIPLE_PX)
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = BACKGROUND
    grid_columns = lefts[10::10] - CELL_GAP_PX
    image[MARGIN_PX : tops[-1] + CELL_HEIGHT_PX, grid_columns] = GRID
    # Map every pixel to the cell it belongs to (-1 in gaps), then paint all cells at once.
    row_of_y = np.full(height, -1)
    for row, top in enumerate(tops):
        row_of_y[top : top + CELL_HEIGHT_PX] = row
    column_of_x = np.full(width, -1)
    for column, left in enumerate(lefts):
        column_of_x[left : left + CELL_WIDTH_PX] = column
    ys, xs = np.flatnonzero(row_of_y >= 0), np.flatnonzero(column_of_x >= 0)
    image[np.ix_(ys, xs)] = _PALETTE[codes[np.ix_(row_of_y[ys], column_of_x[xs])]]
    return image


def _round_up(value: int, multiple: int) -> int:
    return -(-value // multiple) * multiple
