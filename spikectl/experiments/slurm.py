"""``spikectl sweep --backend slurm``: a sweep's trials as Slurm jobs, through submitit.

Each task of a sweep (one trial, or one seed group with ``group_seeds``) is one job, and
the sweep's jobs go to Slurm together as one job array (``sbatch --array``). The trials
train where they would on the local backend (``SWEEP_DIR/trials/NAME``, which must be on
storage that the compute nodes share), so ``spikectl plot SWEEP_DIR`` reads them the same
way; submitit's scripts, pickles and each job's logs go to ``SWEEP_DIR/slurm/``.

Requeue: a job that reaches its time limit, or is preempted, receives submitit's signal
(USR2 by default, ``--signal`` in the sbatch script). submitit then asks the job's
callable for its ``checkpoint()`` and requeues the job with what it returns: here the
same task again, which resumes each trial from its run directory's last ``checkpoint.pt``
(``run_trials``: spikectl's exact resume), so a requeued trial ends bit-identical to one
never stopped; the rounds since that checkpoint are done again. A job lost without the
signal (killed, out of memory, a node down) is reported as failed; running the same
command again resumes its trials the same way.

submitit is an optional extra (``pip install 'spikectl[slurm]'``). This module imports it
only when a sweep runs on this backend, so that the command line's flags
(:class:`SlurmSettings`) never need it, and neither does a job's callable
(:class:`TrialJob`) until it is checkpointed.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from spikectl.config_errors import ConfigError, MissingExtraError, check_int

SLURM_DIR = "slurm"
"""Where in a sweep directory submitit keeps its scripts, pickles and the jobs' logs."""
POLL_S = {"slurm": 10.0, "local": 0.25}
"""How often the sweep's process asks whether jobs have ended (submitit caches sacct)."""


class JobLostError(RuntimeError):
    """A job ended without a result (killed, out of memory, out of requeues); its trials
    resume from their last checkpoints when the same sweep runs again."""


@dataclass(frozen=True)
class SlurmSettings:
    """How each job of a ``--backend slurm`` sweep is submitted (its sbatch options)."""

    partition: str | None = None
    """Slurm partition (sbatch --partition); the cluster's default when not given."""
    time_min: int = 240
    """Time limit of each job in minutes; a job that reaches it is requeued and resumes."""
    cpus_per_task: int = 1
    """CPU cores per job; a trial trains on one thread (as on the local backend)."""
    mem_gb: int | None = None
    """Memory per job in GB (sbatch --mem); the partition's default when not given."""
    gpus_per_node: int = 0
    """GPUs per job, for a config that trains on cuda (e.g. --group-seeds --stacked)."""
    max_timeouts: int = 3
    """Times one job may reach its time limit and be requeued (preemptions are not counted)."""
    additional: str | None = None
    """Other sbatch options as a JSON object, e.g. '{"account": "lab", "qos": "low"}'."""
    cluster: Literal["slurm", "local"] = "slurm"
    """slurm: sbatch; local: submitit's local executor (each job a process here, no cluster)."""

    def __post_init__(self) -> None:
        check_int("time_min", self.time_min, 1, what="a positive number of minutes")
        check_int("cpus_per_task", self.cpus_per_task, 1, what="a positive integer")
        if self.mem_gb is not None:
            check_int("mem_gb", self.mem_gb, 1, what="a positive number of GB")
        check_int("gpus_per_node", self.gpus_per_node, 0, what="a non-negative integer")
        check_int("max_timeouts", self.max_timeouts, 0, what="a non-negative integer")
        _sbatch_options(self.additional)

    @property
    def extra(self) -> dict[str, Any]:
        """The sbatch options of ``additional`` (``{}`` when not given)."""
        return _sbatch_options(self.additional)

    def executor(self, folder: Path, name: str, parallelism: int | None):
        """A submitit executor submitting to ``folder`` with these settings, at most
        ``parallelism`` jobs of an array running at once (Slurm's limits when None)."""
        submitit = import_submitit()
        executor = submitit.AutoExecutor(
            folder=folder, cluster=self.cluster,
            slurm_max_num_timeout=self.max_timeouts, local_max_num_timeout=self.max_timeouts,
        )  # fmt: skip
        executor.update_parameters(
            name=name, timeout_min=self.time_min, cpus_per_task=self.cpus_per_task,
            mem_gb=self.mem_gb, gpus_per_node=self.gpus_per_node or None,
            slurm_partition=self.partition, slurm_array_parallelism=parallelism,
            slurm_additional_parameters=self.extra or None,
        )  # fmt: skip
        return executor


def _sbatch_options(text: str | None) -> dict[str, Any]:
    """``--slurm.additional``'s JSON object of sbatch options (``{}`` when not given)."""
    if text is None:
        return {}
    try:
        options = json.loads(text)
    except ValueError as error:
        raise ConfigError("additional", f"is not valid JSON ({error}): {text!r}") from None
    if not isinstance(options, dict) or not all(
        isinstance(value, (str, int, float, bool)) for value in options.values()
    ):
        raise ConfigError(
            "additional",
            f"must be a JSON object of sbatch options with plain values, e.g. "
            f'{{"account": "lab", "qos": "low"}}, got {text!r}',
        )
    return options


def import_submitit():
    """The submitit module, or a one-line error naming the extra that installs it."""
    try:
        import submitit
    except ImportError:
        raise MissingExtraError(
            "--backend slurm needs submitit, which is not installed: "
            "pip install 'spikectl[slurm]'"
        ) from None
    return submitit


def check_slurm_backend(settings: SlurmSettings) -> None:
    """Refuse, before anything is written, a Slurm sweep that cannot be submitted here."""
    import_submitit()
    if settings.cluster == "slurm" and shutil.which("sbatch") is None:
        raise ValueError(
            "--backend slurm: there is no sbatch on this machine: run the sweep on a Slurm "
            "login node, or try it here with --slurm.cluster local"
        )


class TrialJob:
    """One task of a sweep as a submitit job: ``function(*args)`` (``run_trial`` or
    ``run_trials``), checkpointable as a ``submitit.helpers.Checkpointable`` is (a callable
    whose ``checkpoint()`` returns its own resubmission): requeued after a preemption or
    its time limit, it runs the same task again, which resumes the trials exactly.
    ``returned``: the errors that come back as the job's result (the sweep's trial
    errors), not raised: submitit would keep only a raised error's traceback text, and
    the sweep reports these in one line each (a bug keeps its traceback)."""

    def __init__(
        self,
        function: Callable[..., Any],
        args: tuple,
        returned: tuple[type[BaseException], ...] = (),
    ) -> None:
        self.function = function
        self.args = tuple(args)
        self.returned = tuple(returned)

    def __call__(self) -> Any:
        try:
            return self.function(*self.args)
        except self.returned as error:
            return error

    def checkpoint(self, *args: Any, **kwargs: Any):
        """What submitit requeues on preemption or time limit: this same task (its trials'
        progress is in their run directories, not in this object)."""
        from submitit.helpers import DelayedSubmission

        return DelayedSubmission(self, *args, **kwargs)


def run_with_slurm(
    tasks: list[tuple],
    sweep_dir: Path,
    settings: SlurmSettings,
    parallelism: int | None,
    trial_errors: tuple[type[BaseException], ...],
    echo: Callable[[str], None] = print,
) -> Iterator[Any]:
    """Submit ``tasks`` ((function, args, run_dir) each) as one job array and yield each
    job's result, or its error with ``run_dir`` set on it, as the jobs end (a task's
    ``trial_errors`` come back as its job's result)."""
    submitit = import_submitit()
    from submitit.core.utils import UncompletedJobError

    folder = sweep_dir / SLURM_DIR
    executor = settings.executor(folder, f"spikectl-{sweep_dir.name}", parallelism)
    jobs = executor.submit_array(
        [TrialJob(function, args, trial_errors) for function, args, _ in tasks]
    )
    run_dirs = {id(job): run_dir for job, (_, _, run_dir) in zip(jobs, tasks, strict=True)}
    first, last = jobs[0].job_id, jobs[-1].job_id
    echo(f"submitted {len(jobs)} job(s) ({first}{f' to {last}' if last != first else ''}); "
         f"logs in {folder}")  # fmt: skip
    for job in submitit.helpers.as_completed(jobs, poll_frequency=POLL_S[settings.cluster]):
        run_dir = run_dirs[id(job)]
        try:
            outcome = job.result()
        except UncompletedJobError as error:
            if type(error) is UncompletedJobError:  # not FailedJobError, a raised bug
                error = JobLostError(
                    f"job {job.job_id} ended without a result (state {job.state}; log "
                    f"{job.paths.stderr}); the same command resumes it from its last "
                    "checkpoint"
                )
            outcome = error
        if isinstance(outcome, BaseException):
            outcome.run_dir = str(run_dir)
        yield outcome
