"""A run's progress bar and TensorBoard log: optional views of a run, never its record
(metrics.csv is).

TensorBoard writes from a thread of its own and reports a failure (a full disk) at the
next call; each call here turns an OSError into one FileWriteError naming the log. The
loop logs after metrics.csv and best_model.pt are written, and closes the log after
model.pt, so the run stops with its files and its last checkpoint intact.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from spikectl.files import FileWriteError, describe_os_error

# tqdm's own bar without its estimate of the time left: that estimate averages over the
# first round, which carries the one-time costs (Numba's and PyTorch's compilation, the
# first evaluation) and once predicted four hours for a ten-minute run. The postfix
# carries an honest one instead (RunLogger.eta).
BAR_FORMAT = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}, {rate_fmt}{postfix}]"


class RunLogger:
    """tqdm progress bar (optional) and a TensorBoard writer in ``run_dir/tensorboard``;
    ``resume_dir`` is where the run resumes from (a seed group's directory).

    The bar's ``eta`` is the time left at the pace of the rounds after this process's
    first (``?`` until a second round has ended): evaluation rounds count, compilation
    does not. ``clock`` is the wall clock in seconds (a test passes its own).
    """

    def __init__(
        self,
        run_dir: Path,
        total_episodes: int,
        episodes: int,
        show_progress: bool,
        desc: str,
        resume_dir: Path | None = None,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm.auto import tqdm

        self.log_dir, self.resume_dir = run_dir / "tensorboard", resume_dir or run_dir
        with self._writing():
            # purge_step drops events a killed run logged after its last checkpoint.
            self.writer = SummaryWriter(str(self.log_dir), purge_step=episodes)
        self.bar = tqdm(
            total=total_episodes, initial=episodes, unit="ep", disable=not show_progress,
            dynamic_ncols=True, desc=desc, mininterval=1.0, bar_format=BAR_FORMAT,
        )  # fmt: skip
        self.round: dict[str, str] = {}  # what the last round showed (time left, ...)
        self.last: dict[str, str] = {}  # the last evaluation: its episode and returns
        self.total_episodes, self.clock, self.done = total_episodes, clock, episodes
        # (clock, episodes) at the end of this process's first round; None before it.
        self.paced_from: tuple[float, int] | None = None

    @contextlib.contextmanager
    def _writing(self) -> Iterator[None]:
        try:
            yield
        except FileWriteError:
            raise
        except OSError as error:
            raise FileWriteError(
                error.errno,
                f"cannot write the TensorBoard log {self.log_dir}: {describe_os_error(error)}; "
                "the run stopped with its last checkpoint and metrics.csv intact: free the "
                f"space, then spikectl train --resume {self.resume_dir}",
            ) from error

    def eta(self, done: int) -> str:
        """The time left, ``H:MM:SS`` or ``MM:SS``, at the pace since the first round
        ended; ``?`` while no round after the first has ended."""
        now = self.clock()
        if self.paced_from is None:
            self.paced_from = (now, done)
            return "?"
        since, done_then = self.paced_from
        if done <= done_then or now <= since:
            return "?"
        seconds_per_episode = (now - since) / (done - done_then)
        left = max(self.total_episodes - done, 0) * seconds_per_episode
        return self.bar.format_interval(left)

    def progress(self, episodes: int, collect_return: float, learner: dict[str, str]) -> None:
        self.done += episodes  # the bar counts nothing when it is disabled
        # The postfix first, then the count: the redraw that update() may make shows this
        # round's estimate, not the previous round's. refresh=False: the bar redraws at
        # most every mininterval, not on every round.
        self.round = {"eta": self.eta(self.done), **learner, "collect": f"{collect_return:.3f}"}
        self.bar.set_postfix({**self.round, **self.last}, refresh=False)
        self.bar.update(episodes)

    def log(self, row: dict, learner_fields: tuple[str, ...] = ()) -> None:
        """Write the row's returns, loss and the learner's ``learner_fields`` (those
        that are numbers) to TensorBoard, and show the returns on the bar."""
        with self._writing():
            for key in ("train_return", "test_return", "loss", *learner_fields):
                if key in row and not math.isnan(row[key]):
                    self.writer.add_scalar(key, row[key], row["episode"])
            self.writer.flush()
        # The evaluation's episode beside its returns, and on the line at once: the next
        # round's redraw may be a whole evaluation period away (or never come: the last).
        self.last = {"eval ep": f"{row['episode']}", "train": f"{row['train_return']:.3f}",
                     "test": f"{row['test_return']:.3f}"}  # fmt: skip
        self.bar.set_postfix({**self.round, **self.last}, refresh=True)

    def close(self) -> None:
        self.bar.close()
        with self._writing():
            self.writer.close()
