"""Faults and bad input: ONE table of every bad-input CLI case (command, exit code,
words in the one-line message; no file in the working folder created or changed), and
injected faults (a full disk, a failed rename, SIGTERM and SIGKILL during long commands,
damaged checkpoints and logs, unreachable Ray addresses)."""

from __future__ import annotations

import errno
import hashlib
import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
from finsler.infra import files
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
    np.save(tmp_path / "empty.npy", np.zeros((0, 2, 2)))
    (tmp_path / "text.npy").write_text("0.1, 0.2\n0.3, 0.4\n")
    (tmp_path / "adir").mkdir()
    (tmp_path / "target.json").write_text("{}")
    return tmp_path


_SOLVE = ["solve", "--metric", "euclidean", "--pairs", "p3.npy", "--no-progress", "--out"]
_SWEEP = ["sweep", "--envs", "euclidean", "--methods", "midpoint", "--seeds", "1",
          "--timesteps", "100", "--quiet", "--out", "never"]
_CUDA = __import__("torch").cuda.is_available()

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
    # messages that say what is wrong
    (["certify", "--metric", "matsumoto", "--start", "0.1,0.2", "--goal", "-0.3,0.4",
      "--mesh", "p2"], 2, ["--mesh p2", "matsumoto is 2-D", "coarse, default or fine"]),
    (["solve", "--metric", "euclidean", "--pairs", "text.npy"], 2,
     ["not a readable .npy array", "numpy.save"]),
    (["solve", "--metric", "euclidean", "--pairs", "empty.npy"], 2, ["K >= 1", "(0, 2, 2)"]),
    (["cost", "--metric", "matsumoto", "--start", "1.0000001,0", "--goal", "0,0"], 2,
     ["--start = (1.0000001, 0.0) lies outside"]),
    (["train", "--env", "Matsumoto", "--out", "x"], 2, ["did you mean 'matsumoto'"]),
    (["train", "--env", "matsumoto", "--out", "nothere", "--resume"], 2,
     ["run directory nothere does not exist"]),
    (["report", "--env", "poincare", "--out", "rep"], 2, ["no shipped policy"]),
    # cost: points and names
    (["cost", "--metric", "nope", "--start", "0,0", "--goal", "0,0"], 2, ["unknown metric"]),
    (["cost", "--metric", "matsumoto", "--start", "0,0,0", "--goal", "0,0"], 2, ["needs 2"]),
    (["cost", "--metric", "matsumoto", "--start", "0,x", "--goal", "0,0"], 2,
     ["not a comma-separated"]),
    (["cost", "--metric", "matsumoto", "--start", "0,nan", "--goal", "0,0"], 2, ["NaN or inf"]),
    (["cost", "--metric", "matsumoto", "--start", "2,0", "--goal", "0,0"], 2,
     ["outside the domain"]),
    # train / evaluate: names, options, config fields
    (["evaluate"], 2, ["give --run DIR or --env NAME"]),
    (["evaluate", "--env", "klein"], 2, ["unknown environment"]),
    (["evaluate", "--env", "poincare"], 2, ["no shipped policy"]),
    (["train", "--env", "klein", "--out", "x"], 2, ["unknown environment"]),
    (["train", "--env", "euclidean", "--out", "x", "--method", "sideways"], 2, ["method"]),
    pytest.param(["train", "--env", "euclidean", "--out", "x", "--device", "cuda"], 2, ["CUDA"],
                 marks=pytest.mark.skipif(_CUDA, reason="CUDA present"), id="train cuda"),
    (["train", "--env", "euclidean", "--out", "x", "--timesteps", "0"], 2, ["timesteps"]),
    (["train", "--env", "euclidean", "--out", "x", "--set", "epoch=2"], 2,
     ["unknown config field 'epoch' (did you mean epochs"]),
    (["train", "--env", "euclidean", "--out", "x", "--set", "lr=fast"], 2, ["lr must be float"]),
    (["train", "--env", "euclidean", "--out", "x", "--set", "hidden"], 2, ["FIELD=VALUE"]),
    (["train", "--env", "euclidean", "--out", "x", "--set", "env=carlike"], 2, ["use --env"]),
    # these collided with the options of the same name (a TypeError traceback)
    (["train", "--env", "euclidean", "--out", "x", "--set", "timesteps=5"], 2,
     ["--set timesteps=... is not allowed; use --timesteps"]),
    (["train", "--env", "euclidean", "--out", "x", "--set", "seed=3"], 2, ["use --seed"]),
    (["train", "--env", "matsumoto", "--metric-param", "bogus=1", "--out", "x"], 2,
     ["has no parameter 'bogus'", "height (float)"]),
    (["train", "--env", "matsumoto", "--metric-param", "height=abc", "--out", "x"], 2,
     ["must be float"]),
    # sweep
    ([*_SWEEP, "--envs", "nowhere"], 2, ["unknown environment 'nowhere'"]),
    ([*_SWEEP, "--methods", "midpoint,bogus"], 2, ["unknown variant 'bogus'"]),
    ([*_SWEEP, "--seeds", "0"], 2, ["seeds must be a positive integer"]),
    ([*_SWEEP, "--timesteps", "0"], 2, ["timesteps must be a positive integer"]),
    ([*_SWEEP, "--minutes", "0"], 2, ["minutes must be positive"]),
    ([*_SWEEP, "--workers", "0"], 2, ["--workers must be a positive integer"]),
    ([*_SWEEP, "--set", "no_such_field=1"], 2, ["unknown config field(s) 'no_such_field'"]),
    ([*_SWEEP, "--set", "seed=3"], 2, ["the sweep sets 'seed' itself"]),
    ([*_SWEEP, "--set", "lr=fast"], 2, ["lr must be float"]),
    ([*_SWEEP, "--set", "eval_every"], 2, ["--set expects FIELD=VALUE"]),
    # solve: accuracy and warm starts
    (["solve", "--metric", "matsumoto", "--start", "0.1,0.1", "--goal=-0.2,0.1", "--tol", "-1"],
     2, ["--tol must be a relative tolerance in (0, 1)"]),
    (["solve", "--metric", "matsumoto", "--start", "0.1,0.1", "--goal=-0.2,0.1",
      "--warm-start", "nothere"], 2, ["--warm-start nothere: no such run directory"]),
    # certify, exp, log: what the metric cannot do
    (["certify", "--metric", "panda-pole", "--start", "0,0,0,-1,0,1,0", "--goal",
      "0,0,0,-1,0,1,0"], 2, ["start equals goal"]),  # 7-D is certified since issue 46
    (["certify", "--metric", "matsumoto", "--start", "0.1,0", "--goal", "0.1,0"], 2,
     ["start equals goal"]),
    (["exp", "--metric", "carlike", "--start", "0,0,0", "--velocity", "1,0,0"], 2,
     ["not smooth"]),
    (["log", "--metric", "matsumoto", "--start", "0.1,0.1", "--goal", "0.9,0"], 2,
     ["not strongly convex"]),
]


def _case_id(case) -> str | None:
    if hasattr(case, "marks"):  # a pytest.param carries its own id
        return case.id
    return " ".join(case[0])


@pytest.mark.parametrize(("args", "code", "words"), CASES, ids=[_case_id(c) for c in CASES])
def test_bad_input_gets_one_clear_line_and_changes_nothing(work, args, code, words) -> None:
    before = _digest(work)
    res = CliRunner().invoke(app, args)
    assert res.exit_code == code, res.output
    assert res.output.startswith("error: ") and res.output.count("\n") == 1, res.output
    for w in words:
        assert w in res.output, (w, res.output)
    assert _digest(work) == before  # nothing created, nothing changed


def test_an_odd_segment_count_does_not_call_a_node_the_midpoint(work) -> None:
    res = CliRunner().invoke(app, ["solve", "--metric", "euclidean", "--start", "0,0",
                                   "--goal", "0.5,0", "--segments", "3"])
    assert res.exit_code == 0, res.output
    assert "p_1 (n = 3 is odd: no midpoint node)" in res.output
    assert "midpoint" not in res.output.split("p_1")[0].splitlines()[-1]


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


# ----------------------------------------------------------------------------------------
# SIGTERM during long commands: no process outlives the command, the work done is kept
# ----------------------------------------------------------------------------------------
def _children(pid: int) -> set[int]:
    import subprocess

    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True,
                         text=True).stdout
    return {int(x) for x in out.split()}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead: read its state
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def _geodesics(*args: str, cwd: Path):
    import subprocess
    import sys

    exe = Path(sys.executable).with_name("geodesics")
    return subprocess.Popen([str(exe), *args], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _wait_for(cond, timeout: float = 120.0) -> None:
    import time

    t0 = time.time()
    while not cond():
        if time.time() - t0 > timeout:
            raise AssertionError("timed out")
        time.sleep(0.2)


def _sigterm_leaves_no_process(proc, kids: set[int]) -> None:
    """SIGTERM to a long command: exit 130 with the resume message, and none of its
    processes ``kids`` outlives it."""
    import signal
    import time

    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "interrupted (SIGTERM)" in err and "run the same command to resume" in err
    time.sleep(0.5)
    assert not [k for k in kids if _alive(k)], "a worker outlived the command"


def test_sigterm_during_a_batch_solve_stops_every_worker_and_resume_is_equal(tmp_path):

    import solvers

    m = finsler.get_metric("matsumoto")
    pairs = finsler.sample_pairs(m, 24, 3)
    np.save(tmp_path / "p.npy", pairs)
    proc = _geodesics("solve", "--metric", "matsumoto", "--pairs", "p.npy", "--out", "r.json",
                      "--workers", "2", "--no-progress", cwd=tmp_path)
    parts = tmp_path / "r.json.parts"
    _wait_for(lambda: parts.is_dir() and len(list(parts.glob("*.pkl"))) >= 2)
    kids = _children(proc.pid)
    assert len(kids) >= 2  # the pool's workers (and the resource tracker)
    _sigterm_leaves_no_process(proc, kids)
    kept = len(list(parts.glob("*.pkl")))
    assert 2 <= kept < 24 and not (tmp_path / "r.json").exists()
    # the same command resumes and gives what an uninterrupted solve gives
    proc = _geodesics("solve", "--metric", "matsumoto", "--pairs", "p.npy", "--out", "r.json",
                      "--workers", "2", "--no-progress", cwd=tmp_path)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    import json

    doc = json.loads((tmp_path / "r.json").read_text())
    ref = solvers.solve_batch(m, pairs, workers=1, minmax=True, progress=False)
    got = [r["length"] for r in doc["results"]]
    np.testing.assert_allclose(got, [r.length for r in ref], rtol=1e-12)
    assert not parts.exists()


def test_sigterm_during_a_sweep_keeps_every_run_resumable(tmp_path):
    import time

    proc = _geodesics("sweep", "--envs", "euclidean", "--methods", "midpoint", "--seeds", "2",
                      "--timesteps", "3000000", "--out", "sw", "--quiet", "--set",
                      "eval_every=2", cwd=tmp_path)
    runs = [tmp_path / "sw" / "euclidean" / "midpoint" / f"seed-{s}" for s in (0, 1)]
    _wait_for(lambda: all((r / "checkpoint_latest.pt").is_file() for r in runs))
    time.sleep(1.0)
    kids = _children(proc.pid)
    _sigterm_leaves_no_process(proc, kids)
    import learn

    for r in runs:
        assert learn.runs.run_status(r) == "unfinished"
        learn.storage.load_checkpoint(r / "checkpoint_latest.pt")  # intact


def test_the_numeric_api_refuses_points_outside_the_domain_like_the_cli() -> None:
    """One documented behaviour: numpy / list input is checked (finite, inside the domain);
    torch tensors are the training loop's unchecked fast path; ``check`` forces either."""
    import torch

    m = finsler.get_metric("matsumoto")
    with pytest.raises(finsler.DomainError, match=r"x = \(1\.5, 0\.0\) lies outside"):
        m.cost([[1.5, 0.0]], [[0.0, 0.0]])
    with pytest.raises(finsler.DomainError, match="y row 1"):
        m.cost([[0.0, 0.0], [0.1, 0.0]], [[0.2, 0.0], [2.0, 0.0]])
    with pytest.raises(finsler.InputError, match=r"NaN|finite"):
        m.F([[np.nan, 0.0]], [[1.0, 0.0]])
    with pytest.raises(finsler.DomainError):
        m.path_costs(np.array([[[0.0, 0.0], [0.5, 0.0], [1.2, 0.0]]]))
    with pytest.raises(finsler.DomainError):
        m.segment_length([1.5, 0.0], [0.0, 0.0])
    # the explicit fast paths give the formula's value
    unchecked = float(m.cost([[1.5, 0.0]], [[0.0, 0.0]], check=False)[0])
    fast = float(m.cost(torch.tensor([[1.5, 0.0]]), torch.tensor([[0.0, 0.0]]))[0])
    assert unchecked == pytest.approx(fast, rel=1e-6) and unchecked > 90
    with pytest.raises(finsler.DomainError):
        m.cost(torch.tensor([[1.5, 0.0]]), torch.tensor([[0.0, 0.0]]), check=True)


def test_kill_9_during_checkpoint_writes_leaves_the_previous_checkpoint(tmp_path) -> None:
    """A process writing (large) checkpoints in a loop is killed with SIGKILL at an
    arbitrary moment: the file on disk is always a whole checkpoint that loads."""
    import signal
    import subprocess
    import sys
    import time

    from learn.storage import load_checkpoint

    path = tmp_path / "checkpoint_latest.pt"
    code = (
        "import sys, torch\n"
        "from learn.storage import save_checkpoint\n"
        "step = 0\n"
        "while True:\n"
        "    step += 1\n"
        "    save_checkpoint(sys.argv[1], {'format': 'learn-checkpoint-v1', 'step': step,\n"
        "                    'w': torch.full((1_000_000,), float(step))})\n"
    )
    for delay in (0.8, 1.3, 1.7):
        proc = subprocess.Popen([sys.executable, "-c", code, str(path)])
        _wait_for(path.is_file, timeout=60)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        ck = load_checkpoint(path)
        assert ck["step"] >= 1 and float(ck["w"][0]) == ck["step"] == float(ck["w"][-1])
        path.unlink()


@pytest.mark.parametrize("damage", ["truncate", "garbage", "delete"])
def test_a_damaged_metrics_log_loses_no_rows_on_resume(tmp_path, monkeypatch, damage) -> None:
    """The latest checkpoint keeps its own copy of the metrics rows: resuming a run whose
    metrics.csv was truncated, overwritten or deleted rewrites it whole."""
    import signal

    import learn
    from learn.midpoint.trainer import Trainer
    from learn.storage import read_metrics

    cfg = learn.make_config("euclidean", "midpoint", timesteps=30_000, collection_size=1024,
                            minibatch_size=256, eval_every=2, eval_pairs=10, depth=3)
    full = learn.train_run(cfg, tmp_path / "full", progress=False)
    real, calls = Trainer.update, [0]

    def update(self, *a):
        calls[0] += 1
        if calls[0] == 7:
            os.kill(os.getpid(), signal.SIGTERM)
        return real(self, *a)

    monkeypatch.setattr(Trainer, "update", update)
    with pytest.raises(learn.base.TrainingInterrupted):
        learn.train_run(cfg, tmp_path / "cut", progress=False)
    monkeypatch.undo()
    log = tmp_path / "cut" / "metrics.csv"
    if damage == "truncate":
        log.write_text("\n".join(log.read_text().splitlines()[:2]) + "\n")
    elif damage == "garbage":
        log.write_bytes(os.urandom(300))
    else:
        log.unlink()
    learn.train_run(cfg, tmp_path / "cut", resume=True, progress=False)
    keys = ("iteration", "timesteps", "success_rate", "mean_length")
    want = [{k: r[k] for k in keys} for r in full.history]
    got = [{k: r[k] for k in keys} for r in read_metrics(log)]
    # every row of the uninterrupted run is there, in order, with the same values; the
    # interrupted run has at most one extra row (the checkpoint taken on the signal)
    assert [r for r in got if r in want] == want
    assert len(got) <= len(want) + 1


@pytest.mark.parametrize("address", ["127.0.0.1:1", "ray://127.0.0.1:1", "nohost", "h:99999"])
@pytest.mark.parametrize("command", ["sweep", "solve"])
def test_a_wrong_ray_address_fails_in_seconds_naming_it(work, command, address) -> None:
    """Ray's own client retries an unreachable cluster for minutes: the address is probed
    first, and nothing is written."""
    import time

    pytest.importorskip("ray")
    args = (["sweep", "--envs", "euclidean", "--methods", "midpoint", "--seeds", "1",
             "--out", "sw"] if command == "sweep" else [*_SOLVE, "r.json"])
    before = _digest(work)
    t0 = time.perf_counter()
    res = CliRunner().invoke(app, [*args, "--ray", address])
    assert time.perf_counter() - t0 < 30
    assert res.exit_code == 2, res.output
    assert f"Ray at {address!r}" in res.output or f"--ray address {address!r}" in res.output
    assert _digest(work) == before


def test_a_sweep_run_killed_by_sigkill_is_reported_and_the_others_finish(tmp_path):
    """The OOM killer's SIGKILL on one training process: that run is reported failed (with
    the signal) and kept resumable, the other run finishes, and the next sweep resumes it."""
    import json
    import signal

    import learn

    args = ("sweep", "--envs", "euclidean", "--methods", "midpoint", "--seeds", "2",
            "--timesteps", "100000", "--out", "sw", "--quiet", "--set", "eval_every=2")
    proc = _geodesics(*args, cwd=tmp_path)
    runs = [tmp_path / "sw" / "euclidean" / "midpoint" / f"seed-{s}" for s in (0, 1)]
    _wait_for(lambda: all((r / "checkpoint_latest.pt").is_file() for r in runs))
    workers = [k for k in _children(proc.pid)
               if b"resource_tracker" not in Path(f"/proc/{k}/cmdline").read_bytes()]
    assert len(workers) == 2
    os.kill(workers[0], signal.SIGKILL)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    doc = json.loads((tmp_path / "sw" / "sweep.json").read_text())
    actions = sorted(r["action"] for r in doc["runs"])
    assert actions == ["failed", "started"], doc["runs"]
    failed = next(r for r in doc["runs"] if r["action"] == "failed")
    assert "killed by signal 9" in failed["error"] and "resume" in failed["error"]
    dead = runs[failed["seed"]]
    assert learn.runs.run_status(dead) == "unfinished"
    learn.storage.load_checkpoint(dead / "checkpoint_latest.pt")  # intact
    proc = _geodesics(*args, cwd=tmp_path)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    doc = json.loads((tmp_path / "sw" / "sweep.json").read_text())
    assert sorted(r["action"] for r in doc["runs"]) == ["resumed", "skipped"]
