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
