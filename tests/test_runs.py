"""learn.runs: the paper's variants, run status, start / skip / resume, the run lock."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import finsler
import learn
from learn import runs
from learn.storage import read_json, read_metrics

_TINY = dict(collection_size=1024, minibatch_size=256, eval_every=2, eval_pairs=10, depth=3)


def test_variants_are_the_papers_comparisons() -> None:
    d = runs.make_config("matsumoto", "midpoint", seed=3)
    assert d.seed == 3 and not d.model_free and d.path_energy_weight > 0
    free = runs.make_config("matsumoto", "midpoint-free")
    assert free.model_free and free.path_energy_weight == 0
    # the model-free variant differs from the defaults only in the derivative terms
    assert {k for k, v in free.to_dict().items() if d.to_dict()[k] != v} == {
        "path_energy_weight", "seed"}
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
    assert r["action"] == "started" and r["stopped_by"] == "timesteps"
    assert runs.run_status(out) == "finished"
    files = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    r2 = runs.run_one("euclidean", "midpoint-free", 0, out, timesteps=6000, **_TINY)
    assert r2["action"] == "skipped" and r2["timesteps"] == r["timesteps"]
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == files
    # an interrupted run (no result.json) is resumed and reaches the same end
    ref = read_metrics(out / "metrics.csv")
    (out / "result.json").unlink()
    assert runs.run_status(out) == "unfinished"
    r3 = runs.run_one("euclidean", "midpoint-free", 0, out, timesteps=6000, **_TINY)
    assert r3["action"] == "resumed" and r3["timesteps"] == r["timesteps"]
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
