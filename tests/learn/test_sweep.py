"""`geodesics sweep` (local pool and Ray) and `geodesics solve --ray`: layout, skip, resume,
failures, equality of the backends, and clear errors on bad input."""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import finsler
import learn
import solvers
from learn import run_one, run_status
from learn.storage import load_checkpoint, read_json, read_metrics
from validation.cli import app

runner = CliRunner()

ENV = "matsumoto"
VARIANTS = ("midpoint", "midpoint-free")
T = 10_000
TINY = {"collection_size": 1024, "minibatch_size": 256, "eval_every": 2, "eval_pairs": 20,
        "path_energy_pairs": 1}
RUNS = [f"{ENV}/{v}/seed-{s}" for v in VARIANTS for s in (0, 1)]
WALL_COLUMNS = ("wall_seconds", "evaluations_per_second")


def _sweep(out: Path, *extra: str):
    sets = [a for k, v in TINY.items() for a in ("--set", f"{k}={v}")]
    return runner.invoke(app, ["sweep", "--envs", ENV, "--methods", ",".join(VARIANTS),
                               "--seeds", "2", "--timesteps", str(T), "--out", str(out),
                               "--quiet", *sets, *extra])


def _snapshot(root: Path, runs: list[str]) -> dict[str, tuple[str, int]]:
    """relative path -> (sha256, mtime_ns) of every file of the given runs."""
    out = {}
    for run in runs:
        for p in sorted((root / run).iterdir()):
            out[f"{run}/{p.name}"] = (hashlib.sha256(p.read_bytes()).hexdigest(),
                                      p.stat().st_mtime_ns)
    return out


def _interrupt(root: Path, run: str) -> int:
    """Replace ``run`` by the same run stopped early (a 0.2 s wall limit) without its
    result.json, as a killed sweep leaves it; returns the timesteps it had reached."""
    variant, seed = run.split("/")[1], int(run.rsplit("-", 1)[1])
    shutil.rmtree(root / run)
    res = run_one(ENV, variant, seed, root / run, timesteps=T, minutes=0.2 / 60, **TINY)
    assert res["stopped_by"] == "minutes"
    (root / run / "result.json").unlink()
    assert run_status(root / run) == "unfinished"
    reached = int(load_checkpoint(root / run / "checkpoint_latest.pt")["counters"]["timesteps"])
    assert reached < T
    return reached


def _assert_same_weights(a: Path, b: Path) -> None:
    for name in ("checkpoint_latest.pt", "checkpoint_best.pt"):
        ca, cb = load_checkpoint(a / name), load_checkpoint(b / name)
        for net in ("actor", "critic"):
            assert ca[net].keys() == cb[net].keys()
            for key in ca[net]:
                assert torch.equal(ca[net][key], cb[net][key]), (a, name, net, key)


def _assert_same_metrics(a: Path, b: Path) -> None:
    ra, rb = read_metrics(a / "metrics.csv"), read_metrics(b / "metrics.csv")
    assert len(ra) == len(rb) > 2
    for x, y in zip(ra, rb):
        assert x.keys() == y.keys()
        for key in x:
            if key not in WALL_COLUMNS:
                assert x[key] == y[key] or (x[key] != x[key] and y[key] != y[key]), key


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "local"
    res = _sweep(out, "--workers", "2")
    assert res.exit_code == 0, res.output
    return out, res.output


@pytest.fixture(scope="module")
def ray_local():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    yield ray
    ray.shutdown()


def test_local_sweep_writes_the_layout_and_the_plan(local_sweep) -> None:
    out, output = local_sweep
    assert sorted(str(p.relative_to(out)) for p in out.glob("*/*/seed-*")) == sorted(RUNS)
    for run in RUNS:
        variant, seed = run.split("/")[1], int(run[-1])
        cfg = read_json(out / run / "config.json")
        assert (cfg["config"]["env"], cfg["config"]["seed"]) == (ENV, seed)
        assert cfg["config"]["method"] == "midpoint"
        assert cfg["config"]["collection_size"] == 1024 and cfg["config"]["timesteps"] == T
        # midpoint-free switches every derivative term off; the defaults are as configured
        # (Matsumoto's are model-free since issue 25)
        want = variant == "midpoint-free" or learn.default_config(ENV).model_free
        assert cfg["model_free"] is want
        res = read_json(out / run / "result.json")
        assert res["stopped_by"] == "timesteps" and res["timesteps"] >= T
        assert read_metrics(out / run / "metrics.csv")[-1]["timesteps"] == res["timesteps"]
    # the seed reaches the networks: two seeds, two different initial critics
    a = load_checkpoint(out / RUNS[0] / "checkpoint_latest.pt")["critic"]
    b = load_checkpoint(out / RUNS[1] / "checkpoint_latest.pt")["critic"]
    assert any(not torch.equal(a[k], b[k]) for k in a)

    plan = read_json(out / "sweep.json")
    assert plan["envs"] == [ENV] and plan["variants"] == list(VARIANTS)
    assert (plan["seeds"], plan["timesteps"], plan["minutes"]) == (2, T, None)
    assert plan["overrides"]["midpoint"] == TINY and plan["backend"] == "local"
    assert [r["dir"] for r in plan["runs"]] == RUNS
    for r in plan["runs"]:
        assert (r["status"], r["action"], r["stopped_by"]) == ("finished", "started",
                                                               "timesteps")
        assert r["timesteps"] == read_json(out / r["dir"] / "result.json")["timesteps"]
    assert output.count("started") == 4 and "val. success" in output


def test_rerun_skips_every_run_and_changes_no_file(local_sweep) -> None:
    out, _ = local_sweep
    before = _snapshot(out, RUNS)
    res = _sweep(out)
    assert res.exit_code == 0, res.output
    assert res.output.count("skipped") == 4 and "started" not in res.output
    assert _snapshot(out, RUNS) == before
    assert {r["action"] for r in read_json(out / "sweep.json")["runs"]} == {"skipped"}
    # other settings than the runs': refused before any work
    res = runner.invoke(app, ["sweep", "--envs", ENV, "--methods", "midpoint", "--seeds", "1",
                              "--timesteps", str(2 * T), "--out", str(out), "--quiet"])
    assert res.exit_code == 2 and "other settings" in res.output
    assert _snapshot(out, RUNS) == before


def test_killed_sweep_resumes_unfinished_runs_and_reports_failures(local_sweep,
                                                                   tmp_path) -> None:
    ref, _ = local_sweep
    out = tmp_path / "killed"
    shutil.copytree(ref, out)
    resumed, broken = RUNS[3], RUNS[1]
    _interrupt(out, resumed)
    (out / broken / "result.json").unlink()  # unfinished, with an unreadable checkpoint
    (out / broken / "checkpoint_latest.pt").write_bytes(b"not a checkpoint")
    untouched = [RUNS[0], RUNS[2]]
    before = _snapshot(out, untouched)

    res = _sweep(out, "--workers", "2")
    assert res.exit_code == 1, res.output
    assert "1 run(s) failed" in res.output and f"{broken}: CorruptFileError" in res.output
    assert _snapshot(out, untouched) == before
    # the interrupted run finished, exactly as the uninterrupted one
    assert run_status(out / resumed) == "finished"
    assert read_json(out / resumed / "result.json")["timesteps"] == \
        read_json(ref / resumed / "result.json")["timesteps"]
    _assert_same_weights(out / resumed, ref / resumed)
    runs = {r["dir"]: r for r in read_json(out / "sweep.json")["runs"]}
    assert runs[resumed]["action"] == "resumed" and runs[resumed]["status"] == "finished"
    assert runs[broken]["action"] == "failed" and runs[broken]["status"] == "unfinished"
    assert "CorruptFileError" in runs[broken]["error"]
    assert {runs[r]["action"] for r in untouched} == {"skipped"}


def test_ray_sweep_gives_the_local_pool_runs_and_resumes(local_sweep, ray_local,
                                                         tmp_path) -> None:
    ref, _ = local_sweep
    out = tmp_path / "ray"
    res = _sweep(out, "--ray", "local")
    assert res.exit_code == 0, res.output
    assert read_json(out / "sweep.json")["backend"] == "ray"
    for run in RUNS:
        assert sorted(p.name for p in (out / run).iterdir()) == \
            sorted(p.name for p in (ref / run).iterdir())
        assert read_json(out / run / "config.json")["config"] == \
            read_json(ref / run / "config.json")["config"]
        _assert_same_metrics(out / run, ref / run)
        _assert_same_weights(out / run, ref / run)

    # a killed run is sent to its task, resumed on the worker and written back
    _interrupt(out, RUNS[0])
    before = _snapshot(out, RUNS[1:])
    res = _sweep(out, "--ray", "local")
    assert res.exit_code == 0, res.output
    assert res.output.count("resumed") == 1 and res.output.count("skipped") == 3
    assert _snapshot(out, RUNS[1:]) == before
    _assert_same_weights(out / RUNS[0], ref / RUNS[0])
    assert not list(out.rglob("*.tmp"))


def _solve(*args: str):
    return runner.invoke(app, ["solve", "--metric", "poincare", "--no-progress", *args])


def test_solve_ray_equals_solve_workers_and_resumes_from_parts(ray_local, tmp_path) -> None:
    m = finsler.get_metric("poincare")
    pairs = finsler.sample_pairs(m, 3, 11)
    np.save(tmp_path / "p.npy", pairs)
    res = _solve("--pairs", str(tmp_path / "p.npy"), "--out", str(tmp_path / "local.json"),
                 "--workers", "2")
    assert res.exit_code == 0, res.output
    res = _solve("--pairs", str(tmp_path / "p.npy"), "--out", str(tmp_path / "ray.json"),
                 "--ray", "local", "--chunk-size", "2")
    assert res.exit_code == 0, res.output
    a = json.loads((tmp_path / "local.json").read_text())
    b = json.loads((tmp_path / "ray.json").read_text())
    assert len(b["results"]) == 3 and not (tmp_path / "ray.json.parts").exists()
    for doc in (a, b):
        for row in doc["results"]:
            row.pop("wall_time")
    assert a == b

    # a batch interrupted after two pairs: the Ray run reuses their parts, solves the third
    parts = tmp_path / "parts"
    first = solvers.solve_batch(m, pairs[:2], minmax=True, workers=1, progress=False,
                                checkpoint_dir=parts)
    full = solvers.solve_batch(m, pairs, minmax=True, progress=False, checkpoint_dir=parts,
                               ray_address="local", chunk_size=1)
    assert [r.wall_time for r in full[:2]] == [r.wall_time for r in first]  # loaded
    assert full[2].length == a["results"][2]["length"]
    assert np.array_equal(full[2].points, np.asarray(a["results"][2]["points"]))
    assert len(list(parts.glob("pair_*.pkl"))) == 3


def test_ray_missing_is_a_clear_error(tmp_path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    out = tmp_path / "never"
    res = runner.invoke(app, ["sweep", "--envs", ENV, "--methods", "midpoint", "--seeds", "1",
                              "--out", str(out), "--ray", "local", "--quiet"])
    assert res.exit_code == 2 and "pip install -e '.[distributed]'" in res.output
    assert not out.exists()
    m = finsler.get_metric("poincare")
    np.save(tmp_path / "p.npy", finsler.sample_pairs(m, 2, 0))
    res = _solve("--pairs", str(tmp_path / "p.npy"), "--out", str(tmp_path / "r.json"),
                 "--ray", "local")
    assert res.exit_code == 2 and "pip install -e '.[distributed]'" in res.output
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.json.parts").exists()
