"""Where a sweep's tasks run: a local process pool, Ray tasks, or Slurm jobs.

A :class:`Backend` names one of them with its settings; :meth:`Backend.run` yields each
task's result (or the task's exception, with ``run_dir`` set on it) as tasks finish. Each
trial's result is the same whichever backend ran it (one Torch thread a trial).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from spikectl.config_errors import MissingExtraError
from spikectl.experiments.slurm import SLURM_DIR, SlurmSettings, check_slurm_backend, run_with_slurm

BACKENDS = ("local", "ray", "slurm")

PARENT_POLL_S = 0.2
"""How often (seconds) a local worker checks that the sweep's process is still alive."""


@dataclass(frozen=True)
class Backend:
    """Where a sweep's tasks run.

    ``name="local"``: a process pool of ``workers`` (default: one per core, at most one
    per trial). ``"ray"``: Ray tasks of one CPU each on the cluster at ``address`` (a local
    Ray instance when None); the sweep directory must then be on storage every node sees.
    ``"slurm"``: one Slurm job per task, submitted as one job array with the ``slurm``
    settings (default ``SlurmSettings()``), at most ``workers`` running at once (None:
    Slurm's limits), requeued and resumed on preemption or time limit; its logs in
    ``SWEEP_DIR/slurm``, the sweep directory on storage every node sees.
    """

    name: str = "local"
    workers: int | None = None
    address: str | None = None
    slurm: SlurmSettings | None = None

    def check(self) -> None:
        """One-line errors for settings that do not fit together; Slurm's own checks."""
        if self.name not in BACKENDS:
            raise ValueError(f"backend must be 'local', 'ray' or 'slurm', got {self.name!r}")
        workers = self.workers
        if workers is not None and (
            isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
        ):
            raise ValueError(f"workers must be a positive integer or None, got {workers!r}")
        if self.slurm is not None and self.name != "slurm":
            raise ValueError(f"Slurm settings apply to the slurm backend, not {self.name!r}")
        if self.name == "slurm":
            check_slurm_backend(self.slurm or SlurmSettings())

    def pool_size(self, n_trials: int) -> int:
        """Workers of a local pool or a local Ray instance: as asked, else one per core,
        never more than there are trials."""
        return max(1, min(self.workers or os.cpu_count() or 1, n_trials))

    def describe(self, sweep_dir: Path, n_trials: int) -> str:
        """Where the tasks run, for the sweep's first line."""
        if self.name == "slurm":
            return f"Slurm jobs (logs in {sweep_dir / SLURM_DIR})"
        return f"{self.pool_size(n_trials)} worker(s)"

    def run(
        self,
        tasks: list[tuple],
        sweep_dir: Path,
        n_trials: int,
        trial_errors: tuple[type[BaseException], ...],
        echo: Callable[[str], Any],
    ) -> Iterator[Any]:
        """Each task's result, or its exception with ``run_dir`` set, as tasks finish."""
        if self.name == "slurm":
            slurm = self.slurm or SlurmSettings()
            return run_with_slurm(tasks, sweep_dir, slurm, self.workers, trial_errors, echo)
        if self.name == "ray":
            return _run_with_ray(tasks, self.address, self.pool_size(n_trials))
        return _run_locally(tasks, self.pool_size(n_trials))


def _exit_with_parent(parent_pid: int) -> None:
    """Worker initializer: end this worker as soon as the sweep's process is gone
    (killed, even by SIGKILL), so that no trial outlives it holding its pipes."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="spikectl-parent-watch", daemon=True).start()


def _run_locally(tasks: list[tuple], workers: int):
    """Yield task results (or a task's exception, with ``run_dir`` set on it) as a local
    process pool finishes them."""
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=get_context("spawn"),
        initializer=_exit_with_parent, initargs=(os.getpid(),),
    ) as pool:  # fmt: skip
        futures = {pool.submit(function, *args): run_dir for function, args, run_dir in tasks}
        for future in as_completed(futures):
            error = future.exception()
            if error is None:
                yield future.result()
            else:
                error.run_dir = str(futures[future])
                yield error


def _run_with_ray(tasks: list[tuple], address: str | None, workers: int):
    """Yield task results as Ray tasks (one CPU each) finish them."""
    try:
        import ray
    except ImportError:
        raise MissingExtraError(
            "--backend ray needs Ray, which is not installed: pip install 'spikectl[ray]'"
        ) from None
    started_here = not ray.is_initialized()
    if started_here:
        local = {"num_cpus": workers, "include_dashboard": False} if address is None else {}
        ray.init(address=address, log_to_driver=False, **local)
    try:
        remote = {function: ray.remote(num_cpus=1)(function) for function, _, _ in tasks}
        pending = {remote[function].remote(*args): run_dir for function, args, run_dir in tasks}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            run_dir = pending.pop(done[0])
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayTaskError as wrapped:
                error = wrapped.as_instanceof_cause()
                error.run_dir = str(run_dir)
                yield error
    finally:
        if started_here:
            ray.shutdown()
