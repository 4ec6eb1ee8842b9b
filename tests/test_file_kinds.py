"""What kind of spikectl file a path is (``spikectl.file_kinds``), and every reader that
refuses another kind in one line naming the kind found and the kind it takes."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from spikectl.file_kinds import FileKind, identify
from spikectl.training.run_files import RunDirError

SMOKE_RUN = Path(__file__).parent / "data" / "format2-smoke-run"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[FileKind, Path]:
    """One path of each kind spikectl writes, and of some it does not."""
    from spikectl.agents import export_policy, make_agent
    from spikectl.contexts import make_splits
    from spikectl.training.torch_files import save_model

    root = tmp_path_factory.mktemp("kinds")
    run = root / "run"
    shutil.copytree(SMOKE_RUN, run)
    group = root / "group"
    group.mkdir()
    (group / "group.json").write_text("{}")
    network = make_agent("tdrqn", 5, 20)
    save_model(root, network)  # root/model.pt
    export_policy(network, root / "pol.npz")
    make_splits(3, 3, 5, 20, seed=4)[1].save(root / "ctx.npz")
    (root / "notes.txt").write_text("hello")
    (root / "empty").mkdir()
    return {
        FileKind.RUN_DIR: run,
        FileKind.SEED_GROUP: group,
        FileKind.MODEL: root / "model.pt",
        FileKind.BEST_MODEL: run / "best_model.pt",
        FileKind.CHECKPOINT: run / "checkpoint.pt",
        FileKind.POLICY: root / "pol.npz",
        FileKind.CONTEXT_SET: root / "ctx.npz",
        FileKind.FOLDER: root / "empty",
        FileKind.MISSING: root / "nothing.pt",
        FileKind.OTHER: root / "notes.txt",
    }


def test_each_kind_is_told_from_the_file_itself(files):
    for kind, path in files.items():
        assert identify(path) is kind, path
    assert identify("/dev/null") is FileKind.SPECIAL  # never opened


def test_the_format_names_are_the_writers_own():
    from spikectl import file_kinds
    from spikectl.agents import policy_file
    from spikectl.contexts import file_format
    from spikectl.training import checkpoint, torch_files

    assert file_kinds.MODEL_FORMAT == torch_files.MODEL_FORMAT
    assert file_kinds.CHECKPOINT_FORMAT == checkpoint.CHECKPOINT_FORMAT
    assert file_kinds.POLICY_FORMAT == policy_file.FORMAT_NAME
    assert file_kinds.CONTEXT_SET_FORMAT == file_format.FORMAT_NAME


READERS = {
    "load_controller": ((FileKind.RUN_DIR, FileKind.POLICY), "a controller is a run directory"),
    "ContextSet.load": ((FileKind.CONTEXT_SET,), "a context set is"),
    "CompiledPolicy.load": ((FileKind.POLICY,), "a compiled policy is"),
    "load_model_weights": ((FileKind.MODEL, FileKind.BEST_MODEL), "a model file is"),
    "read_checkpoint": ((FileKind.CHECKPOINT,), "a checkpoint is"),
    "read_config": ((FileKind.RUN_DIR,), "a run directory is a folder spikectl train wrote"),
}
OTHERS = (FileKind.MODEL, FileKind.BEST_MODEL, FileKind.CHECKPOINT, FileKind.POLICY,
          FileKind.CONTEXT_SET)  # fmt: skip


def read(reader: str, path: Path):
    from spikectl.agents.compiled import CompiledPolicy
    from spikectl.contexts import ContextSet
    from spikectl.training.checkpoint import read_checkpoint
    from spikectl.training.loaders import load_controller
    from spikectl.training.run_files import read_config
    from spikectl.training.torch_files import load_model_weights

    return {
        "load_controller": load_controller, "ContextSet.load": ContextSet.load,
        "CompiledPolicy.load": CompiledPolicy.load, "load_model_weights": load_model_weights,
        "read_checkpoint": read_checkpoint, "read_config": read_config,
    }[reader](path)  # fmt: skip


@pytest.mark.parametrize("reader", READERS)
def test_every_reader_names_the_kind_it_was_given_and_the_kind_it_takes(files, reader):
    """A file of another kind is one error naming what it is and what the reader takes,
    not the failure of the library underneath (PyTorch's "[enforce fail at
    inline_container.cc:180]", a missing 'metadata' entry, "written before checksums")."""
    accepted, takes = READERS[reader]
    for kind in OTHERS:
        if kind in accepted:
            continue
        with pytest.raises((ValueError, RunDirError)) as caught:
            read(reader, files[kind])
        message = str(caught.value)
        assert message.startswith(f"{files[kind]} is {kind.value}"), message
        assert takes in message and "\n" not in message, message
        assert "enforce fail" not in message and "before checksums" not in message


def test_the_cli_names_the_kind_in_one_line(files, run_cli):
    result = run_cli("realtime", str(files[FileKind.CONTEXT_SET]), check=False)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"spikectl: error: {files[FileKind.CONTEXT_SET]} is a context set file (.npz); a "
        "controller is a run directory, a compiled policy file (.npz from export_policy), "
        "an amortised belief's weights (.pt: AmortisedController, or with a policy trained "
        "on it: BeliefPolicyController) or one of do-nothing, random, identify-and-plan, "
        "oracle, witness, identify-and-plan-realtime"
    ]


def test_a_header_claiming_gigabytes_allocates_nothing(tmp_path):
    """The kind of an .npz is read from its metadata array's own header first: a header
    claiming a 2 GB string is no context set or policy, and nothing of that size is made."""
    import io
    import tracemalloc
    import zipfile

    import numpy as np

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<U500000000", "fortran_order": False, "shape": ()}
    )
    with zipfile.ZipFile(tmp_path / "bomb.npz", "w") as archive:
        archive.writestr("metadata.npy", header.getvalue() + b"{}" * 50)
    tracemalloc.start()
    try:
        assert identify(tmp_path / "bomb.npz") is FileKind.NPZ_FILE
        assert tracemalloc.get_traced_memory()[1] < 2**24
    finally:
        tracemalloc.stop()
