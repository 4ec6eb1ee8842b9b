"""Issue 26, class 3: a table never shows one environment's numbers under another's
name (``spikectl baselines --env``)."""

from __future__ import annotations

import pytest

from spikectl.cli import main
from spikectl.contexts import ContextSet


@pytest.fixture(scope="module")
def plain_contexts(tmp_path_factory):
    path = tmp_path_factory.mktemp("contexts") / "plain.npz"
    ContextSet.generate(3, n_neurons=8, seed=1).save(path)
    return path


@pytest.mark.parametrize(
    ("env", "problem"),
    [
        ("spikectl/NeuronControlPartial-v0", "were made with context-level extensions none"),
        ("spikectl/NeuronControl32-v0", "have 8 neurons, but spikectl/NeuronControl32-v0 has 32"),
        ("CartPole-v1", "is not a spikectl environment"),
    ],
)
def test_baselines_refuse_contexts_of_another_environment(
    tmp_path, plain_contexts, capsys, env, problem
):
    out = tmp_path / "baselines.csv"
    with pytest.raises(SystemExit) as exit_info:
        main(["baselines", "--env", env, "--contexts", str(plain_contexts), "--out", str(out)])
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert problem in line
    assert not out.exists()


def test_baselines_play_contexts_of_their_own_environment(tmp_path, plain_contexts, capsys):
    out = tmp_path / "baselines.csv"
    main(["baselines", "--env", "spikectl/NeuronControlNoisy-v0", "--contexts",
          str(plain_contexts), "--out", str(out), "--random-seeds", "1",
          "--oracle-width", "8"])  # fmt: skip
    assert "environment spikectl/NeuronControlNoisy-v0" in capsys.readouterr().out
    assert out.exists()
