"""Context generation (docs/model.md), ContextSet files and bring-your-own contexts."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from spikectl import Context, ContextSet, NeuronParams, make_context, make_splits, simulate
from spikectl.contexts import ContextFileError
from spikectl.contexts.generation import (
    CONNECTION_PROBABILITY_BANDS,
    connection_probability,
    generate_context,
    generate_topology,
    legal_actions,
    target_candidates,
)


def test_connection_probability_bands():
    distance = np.array([1, 4, 5, 8, 9, 12, 13, 100])
    expected = [0.3, 0.3, 0.2, 0.2, 0.1, 0.1, 0.01, 0.01]
    np.testing.assert_array_equal(connection_probability(distance), expected)


def test_topology_statistics_match_spec():
    """Connection frequency per distance band and the excitatory fraction, within 4 sigma."""
    rng = np.random.default_rng(123)
    n, networks = 40, 1500
    weights = np.stack([generate_topology(n, rng) for _ in range(networks)])  # [S, n, n]
    index = np.arange(n)
    distance = np.abs(index[:, None] - index[None, :])
    connected = weights != 0
    bands = [(1, 4, 0.3), (5, 8, 0.2), (9, 12, 0.1), (13, n, 0.01)]
    assert [b[2] for b in bands[:3]] == [p for _, p in CONNECTION_PROBABILITY_BANDS]
    for low, high, probability in bands:
        in_band = (distance >= low) & (distance <= high)
        trials = networks * in_band.sum()
        frequency = connected[:, in_band].mean()
        sigma = np.sqrt(probability * (1 - probability) / trials)
        assert abs(frequency - probability) < 4 * sigma, (low, high, frequency)
    # Dale's law: each presynaptic row has one sign. Rows with no edges have no sign,
    # so measure the fraction among neurons with at least one outgoing edge.
    signs = np.sign(weights.sum(axis=2))  # [S, n]
    rows_with_edges = connected.any(axis=2)
    assert ((weights > 0).any(axis=2) & (weights < 0).any(axis=2)).sum() == 0
    excitatory = (signs[rows_with_edges] > 0).mean()
    trials = rows_with_edges.sum()
    assert abs(excitatory - 0.8) < 4 * np.sqrt(0.16 / trials)
    assert not connected[:, index, index].any()


def test_generated_context_satisfies_spec():
    rng = np.random.default_rng(0)
    for _ in range(50):
        context = generate_context(rng, n_neurons=8, episode_length=60)
        assert context.target in target_candidates(context.weights)
        assert (context.weights[:, context.target] > 0).any()
        assert context.pattern.any()
        assert not context.pattern[0]  # from rest the target cannot spike at step 0
        assert set(context.witness.tolist()) <= set(legal_actions(8, context.target).tolist())
        assert context.verify_witness()


def test_generation_works_for_any_n_from_2():
    for n in (2, 3, 12, 64):
        context = ContextSet.generate(3, n_neurons=n, episode_length=30, seed=1)[0]
        assert context.weights.shape == (n, n)
        assert context.verify_witness()


def test_generation_is_seeded_and_prefix_stable():
    a = ContextSet.generate(12, seed=5)
    b = ContextSet.generate(12, seed=5)
    assert a == b and a.checksum() == b.checksum()
    assert ContextSet.generate(4, seed=5) == a[:4]
    assert ContextSet.generate(12, seed=6) != a


def test_topologies_unique_within_and_across_splits():
    train, test = make_splits(n_train=60, n_test=40, n_neurons=3, episode_length=20, seed=0)
    # 3 neurons allow few distinct topologies, so duplicates would appear if not rejected.
    assert len(train) == 60 and len(test) == 40
    assert train.duplicate_topologies() == []
    assert test.duplicate_topologies() == []
    assert train.duplicate_topologies(test) == []


def test_duplicate_detection_can_fail():
    context = ContextSet.generate(2, seed=0)
    doubled = ContextSet([context[0], context[1], context[0]])
    assert doubled.duplicate_topologies() == [(0, 2)]
    assert context.duplicate_topologies(doubled) == [(0, 0), (1, 1)]


def test_test_split_does_not_depend_on_training_size():
    train_small, test_a = make_splits(n_train=10, n_test=20, seed=3)
    train_large, test_b = make_splits(n_train=40, n_test=20, seed=3)
    assert test_a == test_b
    assert train_large[:10] == train_small


def test_save_load_round_trip(tmp_path):
    params = NeuronParams(release_scale=0.7)
    original = ContextSet.generate(7, n_neurons=5, episode_length=25, seed=9, params=params)
    path = original.save(tmp_path / "set.npz")
    loaded = ContextSet.load(path)
    assert loaded == original
    assert loaded.params == params and loaded.seed == 9
    assert [p.name for p in tmp_path.iterdir()] == ["set.npz"]  # no temporary left over
    with np.load(path) as data:  # plain NumPy can read it
        header = json.loads(str(data["metadata"]))
        assert header["format_version"] == 1 and data["weights"].shape == (7, 5, 5)


def test_save_adds_suffix(tmp_path):
    path = ContextSet.generate(2, seed=0).save(tmp_path / "contexts")
    assert path.name == "contexts.npz" and path.exists()


def test_load_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        ContextSet.load(tmp_path / "nope.npz")


def test_load_not_a_context_file(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"this is not a zip file")
    with pytest.raises(ContextFileError, match="not a readable"):
        ContextSet.load(junk)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.arange(3))
    with pytest.raises(ContextFileError, match="not a spikectl context set"):
        ContextSet.load(foreign)


def rewrite(path, **replacements):
    """Copy a saved set, replacing some of its arrays."""
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays.update(replacements)
    np.savez(path, **arrays)


def test_load_damaged_file_fails_the_checksum(tmp_path):
    path = ContextSet.generate(3, seed=0).save(tmp_path / "set.npz")
    with np.load(path) as data:
        patterns = data["patterns"].copy()
    patterns[0, np.flatnonzero(~patterns[0])[5]] = True
    rewrite(path, patterns=patterns)
    with pytest.raises(ContextFileError, match="checksum"):
        ContextSet.load(path)


def test_load_truncated_file(tmp_path):
    path = ContextSet.generate(3, seed=0).save(tmp_path / "set.npz")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ContextFileError):
        ContextSet.load(path)


def test_load_other_format_version(tmp_path):
    path = ContextSet.generate(3, seed=0).save(tmp_path / "set.npz")
    with np.load(path) as data:
        header = json.loads(str(data["metadata"]))
    header["format_version"] = 99
    rewrite(path, metadata=np.array(json.dumps(header)))
    with pytest.raises(ContextFileError, match="version 99"):
        ContextSet.load(path)


def test_load_invalid_contents(tmp_path):
    path = ContextSet.generate(3, seed=0).save(tmp_path / "set.npz")
    with np.load(path) as data:
        weights = data["weights"].copy()
    weights[0, 0, 0] = 1  # a self-connection
    rewrite(path, weights=weights)
    with pytest.raises(ContextFileError, match="diagonal"):
        ContextSet.load(path)
    assert zipfile.is_zipfile(path)


EXTENDED = {"hidden_neurons": 1, "threshold_spread": 0.1, "time_constant_spread": 0.1,
            "synaptic_spread": 0.1}  # fmt: skip
CHANGED_ARRAYS = {
    "short targets": ("targets", lambda a: a[:2], "(3,)"),
    "targets of floats": ("targets", lambda a: a.astype(float), "(3,) (integer)"),
    "float patterns": ("patterns", lambda a: a * 0.5, "(3, 20) (bool)"),
    "a pattern too few": ("patterns", lambda a: a[:2], "(3, 20)"),
    "short witnesses": ("witnesses", lambda a: a[:, :5], "(3, 20)"),
    "flat weights": ("weights", lambda a: a.reshape(-1), "(3, 6, 6)"),
    "weights of another n": ("weights", lambda a: a[:, :5, :5], "(3, 6, 6)"),
    "hidden of another length": ("hidden", lambda a: a[:2], "(3, 1)"),
    "thresholds of another n": ("thresholds_mV", lambda a: a[:, :4], "(3, 6) (float)"),
    "integer time constants": ("time_constants_ms", lambda a: a.astype(int), "(3, 6) (float)"),
    "synaptic scale of another n": ("synaptic_scale", lambda a: a[:, :2], "(3, 6, 6)"),
}


@pytest.mark.parametrize("change", CHANGED_ARRAYS)
def test_each_array_of_a_set_file_is_checked_and_named(tmp_path, change):
    """An array of the wrong length, shape or dtype is one ContextFileError naming the
    array and the shape it must have (a short targets array once said "zip() argument 2
    is shorter than argument 1")."""
    name, damage, expected = CHANGED_ARRAYS[change]
    path = ContextSet.generate(3, 6, 20, seed=0, extensions=EXTENDED).save(tmp_path / "set.npz")
    assert ContextSet.load(path) is not None
    with np.load(path) as data:
        array = data[name]
    rewrite(path, **{name: damage(array)})
    with pytest.raises(ContextFileError) as caught:
        ContextSet.load(path)
    message = str(caught.value)
    assert message.startswith(f"{path} is damaged: its array {name} is "), message
    assert f"has {name} of shape {expected}" in message, message
    assert "zip()" not in message


def test_bring_your_own_connectome():
    weights = np.array([[0, 1, 0], [0, 0, 1], [-1, 0, 0]])
    context = make_context(weights, seed=4, episode_length=30)
    assert context.target in (1, 2) and context.verify_witness()
    # A pattern of one's own with the witness that makes it.
    witness = np.full(30, -1)
    witness[[0, 10]] = 0
    _, spikes = simulate(weights, witness)
    own = make_context(weights, target=1, pattern=spikes[:, 1], witness=witness)
    assert own.pattern.sum() == 2 and own.verify_witness()
    # A pattern without a witness is accepted, with unknown reachability.
    assert make_context(weights, target=1, pattern=spikes[:, 1]).witness is None


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"weights": np.ones((3, 3))}, "diagonal"),
        ({"weights": np.zeros((3, 4))}, "shape"),
        ({"weights": np.zeros((3, 3))}, "excitatory input"),
        ({"target": 3}, "0..2"),
        ({"target": 1, "pattern": np.zeros(30)}, "between 1 and 29"),
        ({"target": 1, "pattern": np.full(30, 2)}, "0/1"),
        ({"target": 1, "pattern": np.eye(30)[3], "witness": np.full(30, -1)}, "does not reproduce"),
        ({"target": 1, "pattern": np.eye(30)[3], "witness": np.full(29, -1)}, "shape"),
        ({"target": 1, "pattern": np.eye(30)[3], "witness": np.full(30, 7)}, "-1..2"),
        ({"target": 1, "witness": np.full(30, -1)}, "without a pattern"),
    ],
)
def test_bad_contexts_raise_clear_errors(kwargs, message):
    arguments = {"weights": np.array([[0, 1, 0], [0, 0, 1], [-1, 0, 0]])} | kwargs
    with pytest.raises((ValueError, TypeError), match=message):
        make_context(**arguments)


def test_context_is_immutable_and_copies_its_inputs():
    weights = np.array([[0, 1], [0, 0]])
    context = make_context(weights, episode_length=20)
    weights[0, 1] = 0
    assert context.weights[0, 1] == 1
    with pytest.raises(ValueError):
        context.weights[0, 1] = 0
    with pytest.raises(AttributeError):
        context.target = 0


def test_context_set_rejects_mixed_shapes_and_non_contexts():
    small = ContextSet.generate(1, n_neurons=4, seed=0)[0]
    large = ContextSet.generate(1, n_neurons=5, seed=0)[0]
    with pytest.raises(ValueError, match="one shape"):
        ContextSet([small, large])
    with pytest.raises(TypeError, match="not a Context"):
        ContextSet([small, "context"])
    with pytest.raises(ValueError, match="at least one"):
        ContextSet([])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"size": 0}, "size"),
        ({"size": 2, "n_neurons": 1}, "n_neurons"),
        ({"size": 2, "episode_length": 1}, "episode_length"),
        ({"size": 2.5}, "size"),
    ],
)
def test_bad_generation_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ContextSet.generate(**kwargs)


def test_make_splits_validates_sizes():
    with pytest.raises(ValueError, match="n_test"):
        make_splits(n_train=3, n_test=0)


def test_context_equality():
    a, b = ContextSet.generate(2, seed=0)
    assert a == Context(a.weights, a.target, a.pattern, a.witness)
    assert a != b
    assert a != Context(a.weights, a.target, a.pattern)


def test_a_pair_of_sets_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    from spikectl.contexts.splits import save_sets

    train, test = make_splits(2, 2, 5, 20, seed=1)
    (tmp_path / "kept.npz").write_text("kept")
    (tmp_path / "test.npz").symlink_to(tmp_path / "kept.npz")
    pair = {tmp_path / "train.npz": train, tmp_path / "test.npz": test}
    with pytest.raises(ValueError, match=r"test.npz is a symbolic link; refusing to replace"):
        save_sets(pair)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.npz", "test.npz"]
    assert (tmp_path / "kept.npz").read_text() == "kept"
    (tmp_path / "test.npz").unlink()
    real_save = ContextSet.save

    def full_disk_on_the_second(self, path):
        if self is test:
            raise OSError(28, "No space left on device")
        return real_save(self, path)

    monkeypatch.setattr(ContextSet, "save", full_disk_on_the_second)
    with pytest.raises(OSError):
        save_sets(pair)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.npz"]  # no temporaries
    monkeypatch.undo()
    assert save_sets(pair) == [tmp_path / "train.npz", tmp_path / "test.npz"]
    assert ContextSet.load(tmp_path / "test.npz") == test


def test_spikectl_contexts_leaves_no_half_pair_beside_a_link(tmp_path, capsys):
    from spikectl.cli import main

    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "kept.npz").write_text("kept")
    (out / "test_contexts.npz").symlink_to(tmp_path / "kept.npz")
    with pytest.raises(SystemExit) as exit:
        main(["contexts", "--out-dir", str(out), "--n-train", "2", "--n-test", "2",
              "--n-neurons", "5", "--episode-length", "20", "--overwrite"])  # fmt: skip
    assert exit.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"spikectl: error: {out / 'test_contexts.npz'} is a symbolic link")
    assert not (out / "train_contexts.npz").exists()
    assert (tmp_path / "kept.npz").read_text() == "kept"
