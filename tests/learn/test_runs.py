"""learn.runs: the paper's variants, run status, start / skip / resume, the run lock."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import finsler
import learn
from finsler.status import RunAction, RunStatus, RunStop
from learn import runs
from learn.storage import read_json, read_metrics

_TINY = dict(collection_size=1024, minibatch_size=256, eval_every=2, eval_pairs=10, depth=3)


def test_variants_are_the_papers_comparisons() -> None:
    # car-like's defaults differentiate C (path energy); the model-free variant differs
    # from them in the derivative terms and in the passes per collection (in its config)
    d = runs.make_config("carlike", "midpoint", seed=3)
    assert d.seed == 3 and not d.model_free and d.path_energy_weight > 0
    free = runs.make_config("carlike", "midpoint-free")
    assert free.model_free and free.path_energy_weight == 0
    assert {k for k, v in free.to_dict().items() if d.to_dict()[k] != v} == {
        "path_energy_weight", "epochs", "seed"}
    assert free.epochs == 2
    # Matsumoto's defaults are model-free already (issue 25): both variants are the same
    d = runs.make_config("matsumoto", "midpoint", seed=3)
    free = runs.make_config("matsumoto", "midpoint-free", seed=3)
    assert d.model_free and free == d and free.epochs == 3
    assert runs.make_config("matsumoto", "inter").method == "inter"
    assert runs.make_config("matsumoto", "inter").model_free
    assert runs.make_config("matsumoto", "two-to-one").method == "two-to-one"
    assert runs.make_config("matsumoto", "paper") == learn.paper_config("matsumoto")
    assert runs.make_config("matsumoto", "paper", timesteps=5, minutes=2.0).timesteps == 5
    with pytest.raises(finsler.InputError, match="unknown variant 'ours'"):
        runs.make_config("matsumoto", "ours")


def test_run_one_starts_skips_and_resumes(tmp_path) -> None:
    out = tmp_path / "euclidean" / "midpoint-free" / "seed-0"
    assert runs.run_status(out) == "absent"
    r = runs.run_one("euclidean", "midpoint-free", 0, out, timesteps=6000, **_TINY)
    assert r["action"] is RunAction.STARTED and r["stopped_by"] == "timesteps"
    assert runs.run_status(out) is RunStatus.FINISHED and RunStatus.FINISHED == "finished"
    files = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    r2 = runs.run_one("euclidean", "midpoint-free", 0, out, timesteps=6000, **_TINY)
    assert r2["action"] is RunAction.SKIPPED and r2["timesteps"] == r["timesteps"]
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == files
    # an interrupted run (no result.json) is resumed and reaches the same end
    ref = read_metrics(out / "metrics.csv")
    (out / "result.json").unlink()
    assert runs.run_status(out) is RunStatus.UNFINISHED
    r3 = runs.run_one("euclidean", "midpoint-free", 0, out, timesteps=6000, **_TINY)
    assert r3["action"] is RunAction.RESUMED and r3["timesteps"] == r["timesteps"]
    assert [row["timesteps"] for row in read_metrics(out / "metrics.csv")] == [
        row["timesteps"] for row in ref]


def test_a_run_stopped_before_its_first_checkpoint_starts_again(tmp_path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.json").write_text("{}")
    assert runs.run_status(out) == "absent"
    r = runs.run_one("euclidean", "midpoint", 1, out, timesteps=3000, **_TINY)
    assert r["action"] == "started"
    assert read_json(out / "config.json")["config"]["seed"] == 1
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    with pytest.raises(finsler.InputError, match="not a run's"):
        runs.run_one("euclidean", "midpoint", 1, other, timesteps=3000, **_TINY)
    assert (other / "notes.txt").read_text() == "keep me"


def test_a_run_in_use_is_refused_and_a_stale_lock_taken_over(tmp_path) -> None:
    out = tmp_path / "run"
    lock = tmp_path / ".run.lock"
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock.write_text(str(holder.pid))
        with pytest.raises(finsler.InputError, match=f"process {holder.pid}"):
            runs.run_one("euclidean", "midpoint", 0, out, timesteps=3000, **_TINY)
        assert not out.exists()
    finally:
        holder.kill()
        holder.wait()
    lock.write_text(str(holder.pid))  # that process is gone: a stale lock
    assert runs.run_one("euclidean", "midpoint", 0, out, timesteps=3000,
                        **_TINY)["action"] == "started"
    assert not lock.exists() and os.path.isdir(out)


def _signal_at(monkeypatch, iteration: int, sig: int) -> None:
    """Send ``sig`` to this process during the ``iteration``-th update of the trainer."""
    import signal as _signal  # noqa: F401  (documents the kind of ``sig``)

    from learn.midpoint.trainer import Trainer

    real = Trainer.update
    calls = [0]

    def update(self, *a):
        calls[0] += 1
        if calls[0] == iteration:
            os.kill(os.getpid(), sig)
        return real(self, *a)

    monkeypatch.setattr(Trainer, "update", update)


@pytest.mark.parametrize("sig_name", ["SIGTERM", "SIGINT"])
def test_a_signal_saves_a_resumable_checkpoint_and_resume_is_exact(
        tmp_path, monkeypatch, sig_name) -> None:
    import signal

    import torch

    cfg = runs.make_config("euclidean", "midpoint", timesteps=30_000, **_TINY)
    full = learn.train_run(cfg, tmp_path / "full", progress=False)
    # the summary is a Result of the status family: the budget ended a finished run
    assert full.status is RunStop.TIMESTEPS and full.converged and full.strict() is full
    doc = full.to_dict()
    assert doc["status"] == "timesteps" and doc["run_dir"] == str(tmp_path / "full")
    assert doc["wall_time"] == full.wall_seconds and "history" not in doc
    before = signal.getsignal(signal.SIGTERM)  # SIG_DFL, or Ray's if a Ray test ran first
    _signal_at(monkeypatch, 5, getattr(signal, sig_name))
    with pytest.raises(learn.base.TrainingInterrupted, match=sig_name) as err:
        learn.train_run(cfg, tmp_path / "cut", progress=False)
    monkeypatch.undo()
    assert err.value.iterations == 5 and err.value.timesteps < full.timesteps
    assert runs.run_status(tmp_path / "cut") == "unfinished"  # no result.json
    # the handlers are back: the next signal is not swallowed
    assert signal.getsignal(signal.SIGTERM) is before
    resumed = learn.train_run(cfg, tmp_path / "cut", resume=True, progress=False)
    assert resumed.timesteps == full.timesteps
    a = learn.storage.load_checkpoint(tmp_path / "full" / "checkpoint_latest.pt")
    b = learn.storage.load_checkpoint(tmp_path / "cut" / "checkpoint_latest.pt")
    for k in a["actor"]:
        assert torch.equal(a["actor"][k], b["actor"][k]), k


def test_train_cli_prints_how_to_resume_after_sigterm(tmp_path, monkeypatch) -> None:
    import signal

    from typer.testing import CliRunner

    from validation.cli import app

    _signal_at(monkeypatch, 3, signal.SIGTERM)
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["train", "--env", "euclidean", "--out", str(out),
                                   "--timesteps", "30000", "--quiet", "--set",
                                   "collection_size=1024", "--set", "eval_every=2"])
    assert res.exit_code == 130, res.output
    assert "interrupted (SIGTERM)" in res.output
    assert f"geodesics train --env euclidean --out {out} --resume" in res.output
    assert (out / "checkpoint_latest.pt").is_file() and not (out / "result.json").exists()


@pytest.mark.parametrize(("variant", "module", "step"), [
    ("pg", "learn.pg", ("PGTrainer", "cycle")),
    ("seq", "learn.seq", ("SeqTrainer", "train_rollout")),
])
def test_baselines_stop_cleanly_on_a_signal_and_resume(tmp_path, monkeypatch, variant,
                                                       module, step) -> None:
    import importlib
    import signal

    cls = getattr(importlib.import_module(module), step[0])
    real = getattr(cls, step[1])
    calls = [0]

    def stepped(self, *a):
        calls[0] += 1
        if calls[0] == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return real(self, *a)

    monkeypatch.setattr(cls, step[1], stepped)
    over = {"eval_pairs": 10, "timesteps": 60_000}
    cfg = runs.make_config("euclidean", variant, **over)
    with pytest.raises(learn.base.TrainingInterrupted, match="SIGTERM"):
        runs.train_run(cfg, tmp_path / "r", progress=False)
    monkeypatch.undo()
    assert runs.run_status(tmp_path / "r") == "unfinished"
    res = runs.train_run(cfg, tmp_path / "r", resume=True, progress=False)
    assert runs.run_status(tmp_path / "r") == "finished"
    # the budget binds at the first step boundary on or after it (PG: before it)
    assert res.timesteps >= 60_000 if variant == "seq" else res.timesteps <= 60_000
