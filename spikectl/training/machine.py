"""machine.json: the machine each start of a run ran on.

Runs are bit-identical only on the same kind of CPU with the same PyTorch and NumPy:
PyTorch picks its CPU kernels (``torch.backends.cpu.get_cpu_capability()``: AVX2,
AVX-512, ...) by what the processor offers, and vectorised kernels round differently
(docs/reliability.md). So each start of a run, and each resume, appends the machine it
ran on to ``RUN_DIR/machine.json`` (written atomically; config.json stays the run's
settings only, which a resume compares exactly), and a run resumed on another kind of
machine says so in one warning.
"""

from __future__ import annotations

import datetime
import os
import platform
import warnings
from pathlib import Path
from typing import Any

from spikectl.files import read_json_file, read_text_file, write_json
from spikectl.training.run_files import MACHINE_FILE

KIND = ("cpu", "cpu_capability", "torch", "numpy")
"""What must be equal for two starts to compute bit for bit the same."""
FLAGS = ("avx2", "avx512f")


def cpu_description(cpuinfo: str | None = None) -> dict[str, Any]:
    """The CPU's model name and whether it offers AVX2 and AVX-512 (None: unknown), from
    /proc/cpuinfo where there is one (Linux), else from ``platform``."""
    if cpuinfo is None:
        try:
            cpuinfo = read_text_file("/proc/cpuinfo", max_bytes=1 << 24)
        except (OSError, ValueError):
            cpuinfo = ""
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        if not line.strip():
            break  # the first processor's block describes them all
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    flags = fields.get("flags")
    return {
        "cpu": fields.get("model name") or platform.processor() or platform.machine(),
        **{flag: None if flags is None else flag in flags.split() for flag in FLAGS},
    }


def this_machine() -> dict[str, Any]:
    """The machine this process computes on: CPU, kernels, libraries, system."""
    import numpy
    import torch

    return {
        **cpu_description(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "torch": torch.__version__,
        "numpy": numpy.__version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }


def record_machine(run_dir: Path, episode: int) -> None:
    """Append this machine to ``run_dir/machine.json`` as a start at ``episode`` (0 for
    the first start); warn (RuntimeWarning) when the run ran on another kind before. A
    damaged file is reported in a warning and kept beside as ``machine.json.damaged``
    (its record of earlier machines is lost to the check, which the warning says), then
    started again: it is a note for people, not something a run needs."""
    path = run_dir / MACHINE_FILE
    starts: list[dict[str, Any]] = []
    problem = None
    try:
        found = read_json_file(path)
        if isinstance(found, dict) and isinstance(found.get("starts"), list):
            starts = [start for start in found["starts"] if isinstance(start, dict)]
            if len(starts) != len(found["starts"]):
                problem = "some of its starts are not records"
        else:
            problem = "it holds no list of starts"
    except FileNotFoundError:
        pass
    except (OSError, ValueError) as error:
        problem = str(error).splitlines()[0] if str(error) else type(error).__name__
    if problem is not None and episode > 0:
        aside = path.with_name(MACHINE_FILE + ".damaged")
        try:
            os.replace(path, aside)
            kept = f"kept as {aside}"
        except OSError:
            kept = "it could not be moved aside"
        warnings.warn(
            f"{path} is damaged ({problem}; {kept}): whether {run_dir} ran before on another "
            "kind of machine cannot be checked; a new record starts with this machine",
            RuntimeWarning,
            stacklevel=2,
        )
    machine = this_machine()
    if episode == 0:
        starts = []  # a run started again from step 0
    before = [start for start in starts if any(start.get(k) != machine[k] for k in KIND)]
    if before:
        other = before[-1]
        warnings.warn(
            f"{run_dir} ran before on another kind of machine ({_kind(other)}); it resumes "
            f"on {_kind(machine)}: runs are bit-identical only on the same kind, so its "
            f"numbers may differ from an uninterrupted run's (see {path})",
            RuntimeWarning,
            stacklevel=2,
        )
    started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    starts.append({"episode": int(episode), "started": started, **machine})
    write_json(path, {"starts": starts})


def _kind(machine: dict[str, Any]) -> str:
    return (
        f"{machine.get('cpu')}, kernels {machine.get('cpu_capability')}, torch "
        f"{machine.get('torch')}, numpy {machine.get('numpy')}"
    )
