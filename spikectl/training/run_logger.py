"""A run's progress bar and TensorBoard log: optional views of a run, never its record
(metrics.csv is)."""

from __future__ import annotations

import math
from pathlib import Path


class RunLogger:
    """tqdm progress bar (optional) and a TensorBoard writer in ``run_dir/tensorboard``."""

    def __init__(
        self, run_dir: Path, total_episodes: int, episodes: int, show_progress: bool, desc: str
    ) -> None:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm.auto import tqdm

        # purge_step drops events a killed run logged after its last checkpoint.
        self.writer = SummaryWriter(str(run_dir / "tensorboard"), purge_step=episodes)
        self.bar = tqdm(
            total=total_episodes, initial=episodes, unit="ep", disable=not show_progress,
            dynamic_ncols=True, desc=desc, mininterval=1.0,
        )  # fmt: skip
        self.last: dict[str, str] = {}

    def progress(self, episodes: int, collect_return: float, learner: dict[str, str]) -> None:
        self.bar.update(episodes)
        # refresh=False: the bar redraws at most every mininterval, not on every round.
        self.bar.set_postfix(**learner, collect=f"{collect_return:.3f}", **self.last, refresh=False)

    def log(self, row: dict) -> None:
        for key in ("train_return", "test_return", "loss", "epsilon"):
            if key in row and not math.isnan(row[key]):
                self.writer.add_scalar(key, row[key], row["episode"])
        self.writer.flush()
        self.last = {"train": f"{row['train_return']:.3f}", "test": f"{row['test_return']:.3f}"}

    def close(self) -> None:
        self.bar.close()
        self.writer.close()
