"""The main job's progress line: its time left is measured after the first round, whose
one-time compilation once made the first estimate hours for a ten-minute run."""

from __future__ import annotations

from spikectl.training.run_logger import RunLogger


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def make_logger(tmp_path, clock, total=1000, episodes=0, show=False):
    return RunLogger(tmp_path, total, episodes, show, "tdrqn", clock=clock)


def test_no_estimate_until_a_round_after_the_first_has_ended(tmp_path):
    clock = FakeClock()
    logger = make_logger(tmp_path, clock)
    clock.now = 600.0  # the first round: 10 minutes of compilation for 10 episodes
    assert logger.eta(10) == "?"
    clock.now = 601.0  # the second round: 10 episodes in a second
    # 980 episodes left at 0.1 s each, the first round's 600 s excluded.
    assert logger.eta(20) == "01:38"
    clock.now = 611.0  # ten more rounds of 1 s: the pace holds
    assert logger.eta(120) == "01:28"
    logger.close()


def test_estimate_counts_slow_evaluation_rounds_after_the_first(tmp_path):
    clock = FakeClock()
    logger = make_logger(tmp_path, clock, total=100)
    clock.now = 50.0
    assert logger.eta(10) == "?"
    clock.now = 51.0 + 9.0  # one round of 1 s and one of 9 s (an evaluation)
    # 20 episodes in 10 s: 70 left take 35 s.
    assert logger.eta(30) == "00:35"
    logger.close()


def test_a_resumed_run_paces_from_its_own_first_round(tmp_path):
    clock = FakeClock()
    logger = make_logger(tmp_path, clock, total=1000, episodes=500)
    clock.now = 300.0
    assert logger.eta(510) == "?"
    clock.now = 302.0
    assert logger.eta(530) == "00:47"  # 470 left at 0.1 s each
    logger.close()


def test_the_bar_shows_the_estimate_and_not_tqdms_own(tmp_path, capsys):
    clock = FakeClock()
    logger = make_logger(tmp_path, clock, total=1000, show=True)
    clock.now = 600.0
    logger.bar.mininterval = 0  # redraw on every update, as after each second of a run
    logger.progress(10, 0.5, {"loss": "0.100"})
    first = capsys.readouterr().err.split("\r")[-1]
    assert "10/1000" in first and "eta=?" in first
    assert "<" not in first  # tqdm's own "elapsed<remaining" is gone
    clock.now = 601.0
    logger.progress(10, 0.5, {"loss": "0.100"})  # the redraw of update() itself
    assert "eta=01:38" in capsys.readouterr().err.split("\r")[-1]
    logger.close()


def test_a_disabled_bar_still_counts_episodes(tmp_path):
    clock = FakeClock()
    logger = make_logger(tmp_path, clock, total=100, show=False)
    logger.progress(10, 0.5, {})
    clock.now = 1.0
    logger.progress(10, 0.5, {})
    assert logger.done == 20 and logger.eta(logger.done) == "00:08"
    logger.close()


def test_an_evaluation_shows_at_once_with_its_episode(tmp_path, capsys):
    """The line shows the latest evaluation as soon as it is made, with the episode it is
    from: a short run once showed the step-0 evaluation until its end."""
    clock = FakeClock()
    logger = make_logger(tmp_path, clock, total=320, show=True)
    logger.log({"episode": 0, "train_return": 0.5, "test_return": 0.501, "loss": float("nan"),
                "epsilon": 1.0})  # fmt: skip
    logger.progress(160, 0.4, {"eps": "0.50"})
    capsys.readouterr()
    logger.log({"episode": 160, "train_return": 0.61, "test_return": 0.532, "loss": 0.1,
                "epsilon": 0.5})  # fmt: skip
    line = capsys.readouterr().err.split("\r")[-1]  # no further round needed
    assert "eval ep=160, train=0.610, test=0.532" in line and "0.501" not in line
    assert "eps=0.50" in line and "collect=0.400" in line  # the round's values stay
    logger.close()


def test_the_last_line_of_a_run_names_every_file_it_wrote(tmp_path):
    from spikectl.cli.training import written_files

    names = ("config.json", "model.pt", "best_model.pt", "checkpoint.pt", "metrics.csv",
             "learning_curve.png", "baselines.json", "machine.json", "train_contexts.npz",
             "test_contexts.npz", "val_contexts.npz", "tensorboard")  # fmt: skip
    for name in names:
        (tmp_path / name).touch()
    listed = written_files(tmp_path, tmp_path / "learning_curve.png").split(", ")
    assert listed[:2] == ["model.pt", "best_model.pt"] and sorted(listed) == sorted(names)
