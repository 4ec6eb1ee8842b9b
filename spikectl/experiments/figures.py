"""Figures, drawn with matplotlib from saved arrays only (never by running anything)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from spikectl.files import atomic_write
from spikectl.neuron.simulator import DO_NOTHING


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float], **kwargs):
    """A new ``(figure, axes)`` made without pyplot, as ``plt.subplots`` would make it.

    A plain ``matplotlib.figure.Figure`` needs no backend and is kept in no global
    registry, so drawing never changes the caller's matplotlib state (backend, current
    figure) and there is nothing to close. Matplotlib is imported here, not at import.
    """
    from matplotlib.figure import Figure

    figure = Figure(figsize=figsize)
    return figure, figure.subplots(nrows, ncols, **kwargs)


def save_figure(figure, path: str | os.PathLike) -> Path:
    """Save atomically: a figure half-written by a crash never replaces a good one."""
    path = Path(path)
    image_format = path.suffix.lstrip(".") or "png"
    return atomic_write(
        path, lambda handle: figure.savefig(handle, format=image_format, dpi=150,
                                            bbox_inches="tight")
    )  # fmt: skip


def plot_episode_raster(
    pattern: np.ndarray,
    actions: np.ndarray,
    spikes: np.ndarray,
    target: int,
    path: str | os.PathLike,
    title: str = "",
) -> Path:
    """Raster of one episode: the target pattern against the target's spikes, the
    stimulations, and every other neuron's spikes.

    ``pattern`` [N] bool, ``actions`` [N] int, ``spikes`` [N, n] bool.
    """
    pattern = np.asarray(pattern, dtype=bool)
    actions = np.asarray(actions)
    spikes = np.asarray(spikes, dtype=bool)
    length, n = spikes.shape
    others = [j for j in range(n) if j != target]
    target_spikes = spikes[:, target]
    steps = np.arange(length)
    figure, axis = subplots(figsize=(10, 1.2 + 0.28 * (n + 2)))
    row_labels = ["pattern", f"target n{target}"] + [f"n{j}" for j in others]
    y = {label: len(row_labels) - 1 - i for i, label in enumerate(row_labels)}

    spike_mark = {"marker": "|", "s": 120}
    stimulus_mark = {"marker": "s", "s": 22, "facecolors": "none", "edgecolors": "tab:blue"}
    target_row = y[f"target n{target}"]
    # (row, steps marked, style): the pattern, then the target's steps classified as in
    # spikectl.envs.render (hit, unwanted spike, missed spike), then every other neuron.
    marks = [
        (y["pattern"], pattern, {**spike_mark, "color": "black", "label": "wanted spike"}),
        (target_row, pattern & target_spikes, {**spike_mark, "color": "tab:green", "label": "hit"}),
        (target_row, ~pattern & target_spikes,
         {**spike_mark, "color": "tab:orange", "label": "unwanted spike"}),
        (target_row, pattern & ~target_spikes, {"marker": "o", "s": 18, "facecolors": "none",
                                                "edgecolors": "tab:red", "label": "missed spike"}),
    ]  # fmt: skip
    for j in others:
        marks.append((y[f"n{j}"], spikes[:, j], {**spike_mark, "color": "black"}))
        marks.append((y[f"n{j}"], actions == j, stimulus_mark))
    for row, marked, style in marks:
        axis.scatter(steps[marked], np.full(marked.sum(), row), **style)
    axis.scatter([], [], marker="s", facecolors="none", edgecolors="tab:blue", label="stimulated")
    axis.set_yticks(list(y.values()), list(y.keys()))
    axis.set_xlim(-0.5, length - 0.5)
    axis.set_ylim(-0.8, len(row_labels) - 0.2)
    axis.set_xlabel("step (ms)")
    axis.axhline(target_row - 0.5, color="0.8", linewidth=0.8)
    stimulations = int((actions != DO_NOTHING).sum())
    axis.set_title(title or f"{stimulations} stimulations")
    axis.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    path = save_figure(figure, path)
    return path


def plot_learning_curve(
    metrics: list[dict[str, float]],
    baselines: dict[str, dict[str, float]],
    path: str | os.PathLike,
    title: str = "",
) -> Path:
    """Greedy return on the training, the unseen test (and validation) contexts against
    environment steps (one run's ``metrics.csv`` rows), with the do-nothing and random levels."""
    steps = np.array([row["env_steps"] for row in metrics])
    figure, axis = subplots(figsize=(6.4, 4.0))
    axis.plot(steps, [row["train_return"] for row in metrics], label="train contexts", marker=".")
    axis.plot(steps, [row["test_return"] for row in metrics], label="unseen test contexts",
              marker=".")  # fmt: skip
    validation = [row.get("val_return", np.nan) for row in metrics]
    if not np.all(np.isnan(validation)):
        axis.plot(steps, validation, label="validation contexts", marker=".", alpha=0.6)
    styles = {"do_nothing": ("do nothing", ":"), "random": ("random", "--")}
    for name, (label, style) in styles.items():
        if name in baselines:
            level = np.mean(list(baselines[name].values()))
            axis.axhline(level, color="0.4", linestyle=style, linewidth=1, label=label)
    axis.set_xlabel("environment steps")
    axis.set_ylabel("greedy return")
    axis.set_title(title)
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8)
    path = save_figure(figure, path)
    return path


TARGET_COLOUR = "tab:green"
EXCITATORY_COLOUR = "black"
INHIBITORY_COLOUR = "tab:red"


def draw_network(context, axis, label: str = "") -> dict[str, list[tuple[int, int]]]:
    """Draw one context's network on ``axis`` (Figure 3 of the paper): neurons in a
    circular layout, the target green, excitatory edges black and inhibitory edges
    red, as arrows from the presynaptic neuron. Returns the drawn edges by kind."""
    import networkx as nx

    weights = np.asarray(context.weights)
    n = weights.shape[0]
    graph = nx.DiGraph()
    graph.add_nodes_from(range(n))
    edges = {"excitatory": [], "inhibitory": []}
    for source, destination in zip(*np.nonzero(weights), strict=True):
        kind = "excitatory" if weights[source, destination] > 0 else "inhibitory"
        edges[kind].append((int(source), int(destination)))
        graph.add_edge(int(source), int(destination))
    position = nx.circular_layout(graph)
    colours = [TARGET_COLOUR if node == context.target else "white" for node in graph.nodes]
    nx.draw_networkx_nodes(graph, position, ax=axis, node_color=colours, edgecolors="black",
                           node_size=420)  # fmt: skip
    nx.draw_networkx_labels(graph, position, ax=axis, font_size=9)
    for kind, colour in (("excitatory", EXCITATORY_COLOUR), ("inhibitory", INHIBITORY_COLOUR)):
        nx.draw_networkx_edges(
            graph, position, ax=axis, edgelist=edges[kind], edge_color=colour, arrows=True,
            arrowstyle="-|>", arrowsize=12, node_size=420, connectionstyle="arc3,rad=0.1",
        )  # fmt: skip
    axis.set_title(label, loc="left")
    axis.set_xlim(-1.25, 1.25)  # circular_layout puts the nodes on the unit circle
    axis.set_ylim(-1.25, 1.25)
    axis.set_axis_off()
    axis.set_aspect("equal")
    return edges


def plot_networks(contexts, path: str | os.PathLike, n_networks: int = 3) -> Path:
    """Figure 3: the first ``n_networks`` generated networks side by side, panels (a),
    (b), (c), ..., in a circular layout (target green, excitatory edges black arrows,
    inhibitory edges red)."""
    contexts = list(contexts)[:n_networks]
    if not contexts:
        raise ValueError("plot_networks needs at least one context")
    from matplotlib.lines import Line2D

    figure, axes = subplots(1, len(contexts), figsize=(3.4 * len(contexts), 3.6), squeeze=False)
    for index, (context, axis) in enumerate(zip(contexts, axes[0], strict=True)):
        draw_network(context, axis, f"({chr(ord('a') + index)})")
    handles = [
        Line2D([], [], color=EXCITATORY_COLOUR, label="excitatory"),
        Line2D([], [], color=INHIBITORY_COLOUR, label="inhibitory"),
        Line2D([], [], marker="o", linestyle="", markerfacecolor=TARGET_COLOUR,
               markeredgecolor="black", label="target neuron"),
    ]  # fmt: skip
    figure.legend(handles=handles, loc="lower center", ncol=3, frameon=False, fontsize=8)
    path = save_figure(figure, path)
    return path
