"""Faults and bad output paths: one table of CLI cases (command, exit code, words in the
message, files that must not change), and injected faults in the one writer of output
files (a full disk, a failed rename)."""

from __future__ import annotations

import errno
import hashlib
import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
from finsler import files
from validation.cli import app


def _digest(root: Path) -> dict[str, str]:
    """Every file under ``root`` (symlinks as their target path) -> content hash."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_symlink():
            out[str(p.relative_to(root))] = "->" + os.readlink(p)
        elif p.is_file():
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[str(p.relative_to(root))] = "dir"
    return out


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    np.save(tmp_path / "p3.npy", finsler.sample_pairs(finsler.get_metric("euclidean"), 3, 1))
    (tmp_path / "adir").mkdir()
    (tmp_path / "target.json").write_text("{}")
    return tmp_path


_SOLVE = ["solve", "--metric", "euclidean", "--pairs", "p3.npy", "--no-progress", "--out"]

# (arguments, exit code, words the message must contain)
CASES = [
    ([*_SOLVE, "p3.npy/r.json"], 2, ["--out", "p3.npy"]),
    ([*_SOLVE, "adir"], 2, ["exists and is a directory", "refusing"]),
    ([*_SOLVE, "/dev/null"], 2, ["is a device", "refusing"]),
    (["solve", "--metric", "euclidean", "--start", "0,0", "--goal", "0.5,0", "--out",
      "/dev/null"], 2, ["is a device"]),
    (["train", "--env", "euclidean", "--out", "p3.npy", "--timesteps", "100"], 2,
     ["p3.npy"]),
    (["train", "--env", "euclidean", "--out", "missing", "--resume"], 2, ["does not exist"]),
    (["train", "--env", "euclidean", "--out", "p3.npy/run", "--timesteps", "100"], 2,
     ["'p3.npy' is a file, not a folder"]),
    # sizes that cannot fit are refused before allocating, with the figure
    (["cost", "--metric", "panda-pole", "--start", "0,0,0,-1,0,1,0", "--goal",
      "1,1,1,-2,1,2,1", "--order", "100000"], 2, ["order 100000 is above 2048"]),
    (["evaluate", "--env", "matsumoto", "--depth", "30"], 2,
     ["depth 30", "GiB", "over the limit", "smaller depth"]),
]


@pytest.mark.parametrize(("args", "code", "words"), CASES,
                         ids=[" ".join(c[0][:1] + c[0][-1:]) for c in CASES])
def test_bad_output_paths_are_refused_before_any_work(work, args, code, words) -> None:
    before = _digest(work)
    res = CliRunner().invoke(app, args)
    assert res.exit_code == code, res.output
    assert res.output.startswith("error: ") and res.output.count("\n") == 1, res.output
    for w in words:
        assert w in res.output, (w, res.output)
    assert _digest(work) == before  # nothing created, nothing changed


def test_a_symlinked_output_is_written_through(work) -> None:
    (work / "link.json").symlink_to("target.json")
    res = CliRunner().invoke(app, [*_SOLVE, "link.json"])
    assert res.exit_code == 0, res.output
    assert (work / "link.json").is_symlink()  # still a link ...
    doc = (work / "target.json").read_text()  # ... whose target got the result
    assert '"metric": "euclidean"' in doc
    assert not list(work.glob("*.tmp")) and not list(work.glob(".*tmp"))


def test_a_full_disk_leaves_the_previous_file_and_no_temporary(tmp_path, monkeypatch) -> None:
    target = tmp_path / "result.json"
    target.write_text("previous")
    real_fsync = os.fsync

    def full(fd):  # the write "succeeds" into the page cache, the flush finds no space
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(files.OutputError, match=r"No space left on device.*unchanged"):
        files.atomic_write_text(target, "new content")
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert target.read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]


def test_a_failed_rename_keeps_the_previous_checkpoint_loadable(tmp_path, monkeypatch) -> None:
    """A crash between writing a checkpoint and renaming it over the old one (as kill -9
    would leave it) keeps the previous checkpoint intact and loadable."""
    from learn.storage import load_checkpoint, save_checkpoint

    path = tmp_path / "checkpoint_latest.pt"
    save_checkpoint(path, {"format": "learn-checkpoint-v1", "step": 1})

    def killed(src, dst):
        raise OSError(errno.EIO, "simulated crash before rename")

    monkeypatch.setattr(os, "replace", killed)
    with pytest.raises(finsler.InputError, match="simulated crash"):
        save_checkpoint(path, {"format": "learn-checkpoint-v1", "step": 2})
    monkeypatch.undo()
    assert load_checkpoint(path)["step"] == 1
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint_latest.pt"]


@pytest.mark.parametrize("damage", ["truncate", "bitflip", "empty"])
def test_damaged_checkpoints_and_metrics_are_named_errors(tmp_path, damage) -> None:
    import learn
    from learn.storage import load_checkpoint, save_checkpoint

    ck = tmp_path / "checkpoint_best.pt"
    save_checkpoint(ck, {"format": "learn-checkpoint-v1", "x": list(range(1000))})
    data = bytearray(ck.read_bytes())
    if damage == "truncate":
        data = data[: len(data) // 2]
    elif damage == "bitflip":
        data[len(data) // 3] ^= 0xFF
        data[len(data) // 2] ^= 0xFF
    else:
        data = bytearray()
    ck.write_bytes(bytes(data))
    with pytest.raises(learn.CorruptFileError, match=r"checkpoint_best\.pt"):
        load_checkpoint(ck)
