"""Figures 3-5 and the results table, drawn from fake saved run directories."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from spikectl.contexts import ContextSet
from spikectl.experiments.figures import draw_network, plot_networks
from spikectl.experiments.report import (
    DO_NOTHING_RETURN,
    draw_training_curves,
    group_runs,
    load_runs,
    mean_curve,
    plot_test_curves_by_size,
    plot_training_curves,
    results_table,
    write_results_table,
)
from spikectl.experiments.stats import bootstrap_ci
from spikectl.training.presets import SMOKE
from spikectl.training.run import METRIC_FIELDS
from spikectl.training.run_files import write_metrics

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
STEPS = (800, 1600, 2400)
# Per (arch, seed): train and test returns at STEPS.
RETURNS = {
    ("tdrqn", 0): ([0.6, 0.7, 0.8], [0.55, 0.6, 0.7]),
    ("tdrqn", 1): ([0.6, 0.8, 0.9], [0.55, 0.7, 0.8]),
    ("tdrqn", 2): ([0.5, 0.6, 0.7], [0.5, 0.5, 0.6]),
    ("tdrqn", 3): ([0.6, 0.7, 1.0], [0.5, 0.6, 0.9]),
    ("drqn", 0): ([0.5, 0.55, 0.6], [0.5, 0.5, 0.5]),
    ("drqn", 1): ([0.5, 0.65, 0.7], [0.5, 0.5, 0.6]),
}


def make_run(root, arch, seed, train, test, steps=STEPS, n_train=6):
    config = SMOKE.with_changes(arch=arch, seed=seed, n_train=n_train)
    run_dir = root / f"{arch}-n{n_train}-s{seed}"
    run_dir.mkdir(parents=True)
    (run_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2))
    rows = [
        {"episode": 40 * (k + 1), "env_steps": step, "updates": 10 * (k + 1), "epsilon": 0.1,
         "train_return": train[k], "test_return": test[k], "loss": float("nan"),
         "wall_time_s": 60.0 * (k + 1) + seed, "cpu_time_s": 30.0 * (k + 1)}
        for k, step in enumerate(steps)
    ]  # fmt: skip
    write_metrics(run_dir, rows, METRIC_FIELDS)
    return run_dir


@pytest.fixture
def runs(tmp_path):
    dirs = [make_run(tmp_path, arch, seed, *values) for (arch, seed), values in RETURNS.items()]
    return load_runs(dirs)


def assert_png(path):
    assert path.exists() and path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_MAGIC


@pytest.fixture
def saved(monkeypatch):
    """The figures the plot functions save, by file name, as they were saved: what a
    test checks is what the PNG shows (lines, labels), not only that a PNG exists."""
    import spikectl.experiments.figures as figures_module
    import spikectl.experiments.report as report_module

    figures = {}
    real_save = figures_module.save_figure

    def record(figure, path):
        figures[Path(path).name] = figure
        return real_save(figure, path)

    monkeypatch.setattr(figures_module, "save_figure", record)
    monkeypatch.setattr(report_module, "save_figure", record)
    return figures


def plotted_lines(axis):
    """{label: (x, y)} of an axis's labelled lines."""
    return {
        line.get_label(): (np.asarray(line.get_xdata()), np.asarray(line.get_ydata()))
        for line in axis.lines
        if not line.get_label().startswith("_")
    }


def test_load_and_group_runs(runs):
    assert len(runs) == 6
    config, metrics = runs[0]
    assert config["agent"]["arch"] == "tdrqn" and config["train"]["seed"] == 0
    assert [row["env_steps"] for row in metrics] == list(STEPS)
    groups = group_runs(runs, "arch")
    assert list(groups) == ["drqn", "tdrqn"]
    assert [len(group) for group in groups.values()] == [2, 4]
    assert group_runs(runs, "agent.arch") == groups  # the tree's dotted name, or the flat one
    pairs = group_runs(runs, ("arch", "env.id"))
    assert list(pairs) == [("drqn", "spikectl/NeuronControl-v0"),
                           ("tdrqn", "spikectl/NeuronControl-v0")]  # fmt: skip


def test_results_table_numbers(runs, tmp_path):
    markdown, rows = results_table(group_runs(runs), n_resamples=500, seed=1)
    by_group = {row["group"]: row for row in rows}
    tdrqn = by_group["tdrqn"]
    train = np.array([0.8, 0.9, 0.7, 1.0])
    test = np.array([0.7, 0.8, 0.6, 0.9])
    assert tdrqn["n_seeds"] == 4 and tdrqn["env_steps"] == 2400
    assert tdrqn["train_mean"] == pytest.approx(0.85)
    assert tdrqn["train_std"] == pytest.approx(np.sqrt(np.mean((train - 0.85) ** 2)))
    assert tdrqn["test_mean"] == pytest.approx(0.75)
    assert tdrqn["test_std"] == pytest.approx(np.std(test))
    assert tdrqn["gap_mean"] == pytest.approx(0.1)
    assert tdrqn["gap_std"] == pytest.approx(0.0, abs=1e-12)
    # IQM of 4 seeds: drop the lowest and the highest, average the middle two.
    assert tdrqn["train_iqm"] == pytest.approx((0.8 + 0.9) / 2)
    assert tdrqn["test_iqm"] == pytest.approx((0.7 + 0.8) / 2)
    low, high = bootstrap_ci(test, n_resamples=500, rng=1)[1:]
    assert (tdrqn["test_iqm_low"], tdrqn["test_iqm_high"]) == pytest.approx((low, high))
    assert tdrqn["test_iqm_low"] <= tdrqn["test_iqm"] <= tdrqn["test_iqm_high"]
    # Every seed's gap is 0.1, so every resample's IQM is too.
    assert (tdrqn["gap_iqm"], tdrqn["gap_iqm_low"], tdrqn["gap_iqm_high"]) == pytest.approx(
        (0.1, 0.1, 0.1)
    )
    drqn = by_group["drqn"]
    assert drqn["train_mean"] == pytest.approx(0.65)
    assert drqn["test_mean"] == pytest.approx(0.55)
    assert drqn["gap_mean"] == pytest.approx(0.1)
    assert drqn["test_iqm"] == pytest.approx(0.55)  # 2 seeds: nothing trimmed
    assert "| tdrqn | 4 | 2400 | 0.850 ± 0.112 | 0.750 ± 0.112 | 0.100 ± 0.000 |" in markdown
    # Minutes of the last row, averaged over the seeds 0..3 (wall) and equal (core).
    assert tdrqn["wall_minutes"] == pytest.approx((60.0 * len(STEPS) + 1.5) / 60)
    assert tdrqn["core_minutes"] == pytest.approx(30.0 * len(STEPS) / 60)
    assert markdown.splitlines()[-1].endswith(
        f"| {(60.0 * len(STEPS) + 1.5) / 60:.1f} | {30.0 * len(STEPS) / 60:.1f} |"
    )

    markdown_path, csv_path = write_results_table(group_runs(runs), tmp_path / "out",
                                                  n_resamples=500, seed=1)  # fmt: skip
    assert markdown_path.read_text() == markdown
    with open(csv_path, newline="") as handle:
        saved = list(csv.DictReader(handle))
    assert [row["group"] for row in saved] == ["drqn", "tdrqn"]
    assert float(saved[1]["test_iqm"]) == pytest.approx(0.75)
    assert float(saved[1]["gap_iqm"]) == pytest.approx(0.1)


def test_mean_curve_equal_and_interpolated_grids(runs, tmp_path):
    tdrqn = group_runs(runs)["tdrqn"]
    curve = mean_curve(tdrqn, "test_return")
    values = np.array([RETURNS[("tdrqn", s)][1] for s in range(4)])
    np.testing.assert_allclose(curve.steps, STEPS)
    np.testing.assert_allclose(curve.mean, values.mean(axis=0))
    np.testing.assert_allclose(curve.std, values.std(axis=0))
    assert curve.n_runs == 4
    # A run evaluated on another grid is interpolated onto the common range.
    other = load_runs([make_run(tmp_path / "x", "tdrqn", 9, [0.5, 0.9], [0.5, 0.9],
                                steps=(800, 2400))])  # fmt: skip
    mixed = mean_curve([tdrqn[0], *other], "train_return")
    np.testing.assert_allclose(mixed.steps, STEPS)
    np.testing.assert_allclose(mixed.mean, [(0.6 + 0.5) / 2, (0.7 + 0.7) / 2, (0.8 + 0.9) / 2])


def test_training_curves_figure(runs, tmp_path):
    figure, curves = draw_training_curves(group_runs(runs))
    left, right = figure.axes
    assert left.get_title() == "training contexts" and right.get_title() == "unseen test contexts"
    for axis, panel in ((left, "train"), (right, "test")):
        levels = [line.get_ydata()[0] for line in axis.lines if line.get_linestyle() == ":"]
        assert levels == [DO_NOTHING_RETURN]
        plotted = {line.get_label(): line.get_ydata() for line in axis.lines}
        for label in ("tdrqn", "drqn"):
            np.testing.assert_allclose(plotted[label], curves[panel][label].mean)
        assert len(axis.collections) == 2  # one shaded band per group
    np.testing.assert_allclose(curves["train"]["drqn"].mean, [0.5, 0.6, 0.65])
    result = plot_training_curves(group_runs(runs), tmp_path / "fig" / "figure4.png")
    assert_png(result.path)
    np.testing.assert_allclose(result.curves["test"]["drqn"].mean, [0.5, 0.5, 0.55])


def test_training_curves_accept_run_directories(tmp_path, saved):
    dirs = [make_run(tmp_path, "tdrqn", seed, *RETURNS[("tdrqn", seed)]) for seed in range(2)]
    result = plot_training_curves({"TDRQN": dirs}, tmp_path / "figure4.png", title="Fig. 4")
    assert_png(result.path)
    np.testing.assert_allclose(result.curves["train"]["TDRQN"].mean, [0.6, 0.75, 0.85])
    figure = saved["figure4.png"]
    assert figure.get_suptitle() == "Fig. 4"
    left, right = figure.axes
    steps, train = plotted_lines(left)["TDRQN"]
    np.testing.assert_allclose(steps, STEPS)
    np.testing.assert_allclose(train, [0.6, 0.75, 0.85])  # the mean of seeds 0 and 1
    np.testing.assert_allclose(plotted_lines(right)["TDRQN"][1], [0.55, 0.65, 0.75])
    assert plotted_lines(right)["do nothing"][1][0] == DO_NOTHING_RETURN
    assert (left.get_xlabel(), left.get_ylabel()) == ("environment steps", "return")


def test_test_curves_by_size(tmp_path, saved):
    dirs = [
        make_run(tmp_path, "tdrqn", seed, [0.6] * 3, [0.5 + 0.1 * seed + 0.001 * n] * 3, n_train=n)
        for n in (10, 100)
        for seed in range(2)
    ]
    groups = group_runs(load_runs(dirs), "n_train")
    assert list(groups) == [10, 100]
    result = plot_test_curves_by_size(groups, tmp_path / "figure5.png")
    assert_png(result.path)
    (axis,) = saved["figure5.png"].axes
    lines = plotted_lines(axis)
    assert set(lines) == {"10 training contexts", "100 training contexts", "do nothing"}
    np.testing.assert_allclose(lines["100 training contexts"][1], [0.65] * 3)
    np.testing.assert_allclose(lines["10 training contexts"][1], [0.56] * 3)
    assert axis.get_title() == "unseen test contexts"
    np.testing.assert_allclose(result.curves["test"][100].mean, [0.65] * 3)
    np.testing.assert_allclose(result.curves["test"][10].mean, [0.56] * 3)
    np.testing.assert_allclose(result.curves["test"][10].std, [0.05] * 3)


def test_empty_groups_are_errors(tmp_path):
    with pytest.raises(ValueError, match="no groups"):
        results_table({})
    with pytest.raises(ValueError, match="no runs"):
        plot_training_curves({"tdrqn": []}, tmp_path / "x.png")


def test_networks_figure(tmp_path, saved):
    contexts = ContextSet.generate(3, seed=0)
    path = plot_networks(contexts, tmp_path / "figure3.png")
    assert_png(path)
    figure = saved["figure3.png"]
    assert [axis.get_title(loc="left") for axis in figure.axes] == ["(a)", "(b)", "(c)"]
    legend_labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert legend_labels == ["excitatory", "inhibitory", "target neuron"]
    for context, axis in zip(contexts, figure.axes, strict=True):
        nodes = axis.collections[0]  # networkx draws the nodes first
        colours = nodes.get_facecolors()
        green = [i for i, colour in enumerate(colours) if colour[1] > 0.4 and colour[0] < 0.3]
        assert len(colours) == 8 and green == [context.target]


def test_learning_curve_figure(tmp_path, saved):
    from spikectl.experiments.figures import plot_learning_curve

    metrics = [
        {"env_steps": 100, "train_return": 0.55, "test_return": 0.52, "val_return": 0.53},
        {"env_steps": 200, "train_return": 0.65, "test_return": 0.60, "val_return": 0.61},
    ]
    baselines = {"do_nothing": {"train": 0.5, "test": 0.5}, "random": {"train": 0.50, "test": 0.52}}
    plot_learning_curve(metrics, baselines, tmp_path / "curve.png", title="seed 0")
    (axis,) = saved["curve.png"].axes
    lines = plotted_lines(axis)
    np.testing.assert_allclose(lines["train contexts"][0], [100, 200])
    np.testing.assert_allclose(lines["train contexts"][1], [0.55, 0.65])
    np.testing.assert_allclose(lines["unseen test contexts"][1], [0.52, 0.60])
    np.testing.assert_allclose(lines["validation contexts"][1], [0.53, 0.61])
    assert lines["do nothing"][1][0] == 0.5 and lines["random"][1][0] == pytest.approx(0.51)
    assert (axis.get_xlabel(), axis.get_ylabel(), axis.get_title()) == (
        "environment steps", "greedy return", "seed 0"
    )
    # Without validation returns there is no validation line.
    plot_learning_curve([{k: v for k, v in row.items() if k != "val_return"} for row in metrics],
                        {}, tmp_path / "bare.png")  # fmt: skip
    assert set(plotted_lines(saved["bare.png"].axes[0])) == {"train contexts",
                                                             "unseen test contexts"}  # fmt: skip


def test_episode_raster_figure(tmp_path, saved):
    from spikectl.experiments.figures import plot_episode_raster

    pattern = np.array([1, 0, 1, 0, 0, 1], dtype=bool)
    spikes = np.zeros((6, 3), dtype=bool)
    spikes[[0, 3], 1] = True  # target 1: a hit at step 0, an unwanted spike at step 3
    spikes[4, 2] = True
    actions = np.array([-1, 2, -1, 2, -1, -1])
    plot_episode_raster(pattern, actions, spikes, target=1, path=tmp_path / "raster.png")
    (axis,) = saved["raster.png"].axes
    marked = {}
    for collection in axis.collections:
        marked.setdefault(collection.get_label(), []).append(collection.get_offsets())
    steps = {label: sorted(int(x) for offsets in marked[label] for x, _ in offsets)
             for label in ("wanted spike", "hit", "unwanted spike", "missed spike", "stimulated")}
    assert steps == {"wanted spike": [0, 2, 5], "hit": [0], "unwanted spike": [3],
                     "missed spike": [2, 5], "stimulated": []}  # fmt: skip
    labels = [tick.get_text() for tick in axis.get_yticklabels()]
    assert labels == ["pattern", "target n1", "n0", "n2"]
    # Stimulations are open blue squares on the stimulated neuron's row (n2: y = 0).
    squares = [(int(x), int(y)) for c in axis.collections if c.get_label().startswith("_")
               and len(c.get_offsets()) and c.get_facecolors().size == 0
               for x, y in c.get_offsets()]  # fmt: skip
    assert sorted(squares) == [(1, 0), (3, 0)]
    assert axis.get_title() == "2 stimulations"


def test_network_edges_by_sign():
    from spikectl.experiments.figures import subplots

    context = ContextSet.generate(1, seed=0)[0]
    _, axis = subplots(figsize=(3, 3))
    edges = draw_network(context, axis, "(a)")
    weights = np.asarray(context.weights)
    assert sorted(edges["excitatory"]) == sorted(map(tuple, np.argwhere(weights > 0).tolist()))
    assert sorted(edges["inhibitory"]) == sorted(map(tuple, np.argwhere(weights < 0).tolist()))
