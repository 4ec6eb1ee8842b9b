"""The golden runs: what the trainer produced before the one-loop refactor (issue 22).

``python tests/golden/golden_runs.py`` trains each run below through the command line
and writes this machine's record, ``records/<kind>.json``: every metrics.csv column but
the clocks, and a digest of every saved network. tests/test_golden.py trains them again
and must find the same.

A record is bit-exact only on the CPU kind, PyTorch and NumPy it names (``machine``):
PyTorch's kernels round differently on other CPUs. So there is one record per kind. The
first, of the AMD EPYC (AVX2) this project runs on, was made on the commit before the
refactor and is the *reference* the portable tier compares every kind with, within
tolerances; a record of a new kind is made by running this script on it (it refuses to
replace a kind's record: ``--replace`` does, after a deliberate change). Seed groups are
recorded as the seeds trained alone: since the refactor a seed trained in a group gives
exactly the metrics and weights of that seed alone. The group as it trained before the
refactor (one stacked computation: ``train smoke --seeds 0 1`` then) is recorded too, as
``smoke-stacked-group-seed0`` and ``-seed1``; today ``--stacked`` trains that way.
"""

from __future__ import annotations

import hashlib
import json
import platform
import re
import subprocess
import sys
from pathlib import Path

import torch

RECORDS = Path(__file__).with_name("records")
REFERENCE_FILE = RECORDS / "amd-epyc-e2c88bafb1f0c9e3-avx2-torch2.13.0+cpu-numpy2.4.6.json"
"""The record made before the refactor, which the portable tier compares every kind with."""
CLOCKS = ("wall_time_s", "cpu_time_s", "eval_cpu_time_s")
"""The clock columns (spelled out, not imported: this script must run on old commits)."""

QUICK_PREFIX = (
    "train", "quick", "--n-train", "20", "--n-test", "10", "--n-val", "10",
    "--total-env-steps", str(16 * 60 * 6), "--eval-every-episodes", "32",
    "--checkpoint-every-episodes", "32", "--no-progress",
)  # fmt: skip
"""The quick preset with every option it has (n-step, auxiliary loss, pooled head,
learning-rate decay, sparse exploration) over 6 rounds on small sets."""

RUNS: dict[str, tuple[str, ...]] = {
    "quick-prefix": QUICK_PREFIX,
    "smoke-seed0": ("train", "smoke"),
    "smoke-seed1": ("train", "smoke", "--seed", "1"),
}
STACKED_GROUP = ("train", "smoke", "--seeds", "0", "1")
"""The command that recorded the stacked group before the refactor (``--stacked`` today:
``stacked_flag``)."""
SAVED_MODELS = ("model.pt", "best_model.pt")


def machine() -> dict[str, str]:
    """What bit-exactness depends on: the CPU's model and features, the kernel level
    PyTorch dispatches to (AVX2, AVX512, ... or another under ATEN_CPU_CAPABILITY),
    PyTorch, NumPy."""
    import numpy

    cpu = {"model": platform.processor(), "flags": ""}
    try:
        text = Path("/proc/cpuinfo").read_text()
        for line in text.splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name":
                cpu["model"] = value.strip()
            if key.strip() == "flags":
                cpu["flags"] = hashlib.sha256(value.strip().encode()).hexdigest()[:16]
                break
    except OSError:
        pass
    return {"cpu": cpu["model"], "cpu_flags": cpu["flags"],
            "kernels": torch.backends.cpu.get_cpu_capability(), "torch": torch.__version__,
            "numpy": numpy.__version__}  # fmt: skip


def weights_digest(path: Path) -> str:
    """SHA-256 over a saved state dict's names, dtypes, shapes and bytes, in name order."""
    weights = torch.load(path, weights_only=True)
    digest = hashlib.sha256()
    for name in sorted(weights):
        tensor = weights[name].contiguous()
        digest.update(f"{name}{tensor.dtype}{tuple(tensor.shape)}".encode())
        digest.update(tensor.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def record(run_dir: Path) -> dict:
    """A run directory's metrics without the clocks (floats as repr) and model digests."""
    import csv

    with open(run_dir / "metrics.csv", newline="") as handle:
        rows = [
            {key: value for key, value in row.items() if key not in CLOCKS}
            for row in csv.DictReader(handle)
        ]
    return {
        "metrics": rows,
        "models": {name: weights_digest(run_dir / name) for name in SAVED_MODELS
                   if (run_dir / name).exists()},  # fmt: skip
    }


def train(args: tuple[str, ...], run_dir: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "spikectl.cli", *args, "--run-dir", str(run_dir)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip


def stacked_flag() -> tuple[str, ...]:
    """``--stacked`` where the trainer has it (since the refactor a seed group trains each
    seed alone unless told); nothing before it, when a group trained stacked."""
    help_text = subprocess.run(
        [sys.executable, "-m", "spikectl.cli", "train", "smoke", "--help"],
        check=True, capture_output=True, text=True,
    ).stdout  # fmt: skip
    return ("--stacked",) if "--stacked" in help_text else ()


def record_file(kind: dict[str, str]) -> Path:
    """Where the record of a machine kind lives: a name made of what bit-exactness
    depends on (the flags as their digest)."""
    name = "-".join([kind["cpu"], kind["cpu_flags"], kind["kernels"], "torch" + kind["torch"],
                     "numpy" + kind["numpy"]])  # fmt: skip
    return RECORDS / (re.sub(r"[^A-Za-z0-9.+]+", "-", name).strip("-").lower() + ".json")


def load_record(kind: dict[str, str]) -> dict | None:
    """The record of this machine kind, or None where none was made."""
    path = record_file(kind)
    if not path.exists():
        return None
    saved = json.loads(path.read_text())
    return saved if saved["machine"] == kind else None


def main() -> None:
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--replace", action="store_true",
                        help="replace this kind's record (after a deliberate change)")  # fmt: skip
    replace = parser.parse_args().replace
    kind = machine()
    path = record_file(kind)
    if path.exists() and not replace:
        raise SystemExit(f"{path} exists: a record guards this kind; --replace replaces it")
    with tempfile.TemporaryDirectory() as scratch:
        runs = {}
        for name, args in RUNS.items():
            train(args, Path(scratch) / name)
            runs[name] = record(Path(scratch) / name)
        group = Path(scratch) / "group"
        train((*STACKED_GROUP, *stacked_flag()), group)
        for seed in (0, 1):
            runs[f"smoke-stacked-group-seed{seed}"] = record(group / f"seed={seed}")
    RECORDS.mkdir(exist_ok=True)
    path.write_text(json.dumps({"machine": kind, "runs": runs}, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
