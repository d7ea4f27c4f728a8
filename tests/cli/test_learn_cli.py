"""`geodesics train` / `geodesics evaluate`: happy paths and clear errors on bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
import learn
from validation.cli import app

runner = CliRunner()


def _run(*args: str):
    return runner.invoke(app, list(args))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "run"
    res = _run("train", "--env", "euclidean", "--out", str(out), "--timesteps", "20000",
               "--quiet")
    assert res.exit_code == 0, res.output
    assert "evaluations of C/s" in res.output
    return out


def test_train_writes_a_complete_run_directory(run_dir) -> None:
    names = {p.name for p in run_dir.iterdir()}
    assert {"config.json", "metrics.csv", "checkpoint_latest.pt", "checkpoint_best.pt"} <= names
    rows = learn.storage.read_metrics(run_dir / "metrics.csv")
    assert rows[0]["timesteps"] == 0 and rows[-1]["timesteps"] >= 20000
    for key in ("wall_seconds", "success_rate", "mean_length", "critic_loss", "actor_loss",
                "evaluations_per_second"):
        assert key in rows[-1]


def test_evaluate_json_on_default_and_given_pairs(run_dir, tmp_path) -> None:
    res = _run("evaluate", "--run", str(run_dir), "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert {"success_rate", "mean_length", "mean_max_segment_cost", "per_pair"} <= set(doc)
    assert len(doc["per_pair"]) == 100
    assert set(doc["per_pair"][0]) == {"success", "length", "max_segment_cost"}
    # the JSON agrees with the Python API
    ev = learn.load_policy(run_dir).evaluate()
    assert doc["success_rate"] == ev.success_rate
    pairs = finsler.sample_pairs(finsler.get_metric("euclidean"), 5, seed=1)
    np.save(tmp_path / "p.npy", pairs)
    res = _run("evaluate", "--run", str(run_dir), "--pairs", str(tmp_path / "p.npy"),
               "--eps", "0.5", "--depth", "2", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert len(doc["per_pair"]) == 5 and doc["eps"] == 0.5 and doc["depth"] == 2


def test_evaluate_missing_run_dir(tmp_path) -> None:
    res = _run("evaluate", "--run", str(tmp_path / "absent"))
    assert res.exit_code == 2
    assert "does not exist" in res.output


def test_evaluate_corrupt_checkpoint(run_dir, tmp_path) -> None:
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(run_dir, bad)
    (bad / "checkpoint_best.pt").write_bytes(b"\x00garbage")
    res = _run("evaluate", "--run", str(bad))
    assert res.exit_code == 2
    assert "corrupt" in res.output and "checkpoint_best.pt" in res.output


def test_evaluate_pairs_of_wrong_dim(run_dir, tmp_path) -> None:
    np.save(tmp_path / "p3.npy", np.zeros((4, 2, 3)))
    res = _run("evaluate", "--run", str(run_dir), "--pairs", str(tmp_path / "p3.npy"))
    assert res.exit_code == 2
    assert "(K, 2, 2)" in res.output
    (tmp_path / "junk.npy").write_bytes(b"junk")
    res = _run("evaluate", "--run", str(run_dir), "--pairs", str(tmp_path / "junk.npy"))
    assert res.exit_code == 2 and "not a readable .npy" in res.output
    np.save(tmp_path / "out.npy", np.full((2, 2, 2), 5.0))
    res = _run("evaluate", "--run", str(run_dir), "--pairs", str(tmp_path / "out.npy"))
    assert res.exit_code == 2 and "outside the domain" in res.output


def test_train_set_overrides_config_fields(tmp_path) -> None:
    out = tmp_path / "run"
    res = _run("train", "--env", "euclidean", "--out", str(out), "--timesteps", "3000",
               "--quiet", "--set", "hidden=[16,8]", "--set", "path_energy_weight=0.5",
               "--set", "activation=tanh")
    assert res.exit_code == 0, res.output
    cfg = json.loads((out / "config.json").read_text())["config"]
    assert cfg["hidden"] == [16, 8] and cfg["path_energy_weight"] == 0.5
    assert cfg["activation"] == "tanh"
    pol = learn.load_policy(out)
    assert [m.out_features for m in pol.actor.net if hasattr(m, "out_features")] == [16, 8, 4]
    # resuming with a different value of a run-defining field is refused
    res = _run("train", "--env", "euclidean", "--out", str(out), "--resume", "--quiet",
               "--set", "path_energy_weight=2")
    assert res.exit_code == 2 and "path_energy_weight" in res.output


def test_train_refuses_existing_dir_and_resume_of_missing(run_dir, tmp_path) -> None:
    res = _run("train", "--env", "euclidean", "--out", str(run_dir), "--timesteps", "100")
    assert res.exit_code == 2 and "--resume" in res.output
    res = _run("train", "--env", "euclidean", "--out", str(tmp_path / "none"), "--resume")
    assert res.exit_code == 2 and "does not exist" in res.output


@pytest.mark.parametrize("env", ["matsumoto", "carlike", "panda-pole"])
def test_shipped_policy_evaluates_as_recorded(env, tmp_path) -> None:
    """`geodesics evaluate --env NAME` works from the package data and reproduces the
    success rate recorded when the policy was exported, on the set it was recorded on
    (the default evaluation set for the policies trained before the validation set
    existed, the validation set of the run's size otherwise: the config says which)."""
    assert env in learn.shipped_policies()
    doc = json.loads((learn.loop.shipped_dir(env) / "config.json").read_text())
    args = ["evaluate", "--env", env, "--json"]
    if "validation_pairs" in doc["selection"]:
        metric = finsler.get_metric(env)
        pairs = finsler.validation_pairs(metric, doc["config"]["eval_pairs"])
        np.save(tmp_path / "val.npy", pairs)
        args += ["--pairs", str(tmp_path / "val.npy")]
    res = _run(*args)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    recorded = learn.storage.load_checkpoint(
        learn.loop.shipped_dir(env) / "policy.pt")["eval"]
    assert doc["success_rate"] == pytest.approx(recorded["success_rate"])
    assert doc["mean_length"] == pytest.approx(recorded["mean_length"], rel=1e-6)
    pol = learn.load_policy(env)
    p = finsler.default_pairs(pol.metric, 3)
    assert pol.generate(p[:, 0], p[:, 1]).shape == (3, 2**pol.depth + 1, pol.metric.dim)


@pytest.mark.parametrize("env", ["matsumoto", "panda-pole"])
def test_evaluate_says_where_a_shipped_checkpoint_was_selected(env) -> None:
    """On the default pairs the note names the set the shipped checkpoint was chosen on
    (every shipped policy: the validation set since issue 25)."""
    res = _run("evaluate", "--env", env, "--json")
    assert res.exit_code == 0, res.output
    note = json.loads(res.output)["pairs_note"]
    assert "selected on the validation set" in note and "optimistic" not in note


def test_evaluate_flags_a_checkpoint_chosen_on_the_default_pairs(monkeypatch) -> None:
    """A shipped policy whose checkpoint was chosen on the default pairs (the Panda policy
    replaced in issue 25, read from its run's config) gets the "optimistic" note."""
    from pathlib import Path

    old = Path(__file__).resolve().parents[2] / "benchmarks" / "previous_policies" / "panda-pole"
    monkeypatch.setattr(learn.runs, "shipped_dir", lambda name: old)
    res = _run("evaluate", "--env", "panda-pole", "--json")
    assert res.exit_code == 0, res.output
    note = json.loads(res.output)["pairs_note"]
    assert "default evaluation pairs" in note and "optimistic" in note


def test_load_policy_rejects_env_mismatch() -> None:
    import learn
    from finsler.errors import InputError

    assert learn.load_policy("matsumoto", env="matsumoto").metric.name == "matsumoto"
    with pytest.raises(InputError, match="does not match the run's environment matsumoto"):
        learn.load_policy("matsumoto", env="carlike")


def test_evaluate_names_the_checkpoint_and_takes_latest(run_dir) -> None:
    best = json.loads(_run("evaluate", "--run", str(run_dir), "--json").output)
    latest = json.loads(_run("evaluate", "--run", str(run_dir), "--json", "--checkpoint",
                             "latest").output)
    assert best["checkpoint"] == "checkpoint_best.pt"
    assert latest["checkpoint"] == "checkpoint_latest.pt"
    want = learn.load_policy(run_dir, checkpoint="latest").evaluate()
    assert latest["mean_length"] == pytest.approx(want.mean_length, rel=1e-12)
    res = _run("evaluate", "--run", str(run_dir), "--checkpoint", "newest")
    assert res.exit_code == 2 and "best or latest" in res.output
    res = _run("evaluate", "--run", str(run_dir))
    assert "(checkpoint_best.pt)" in res.output


def test_model_free_flag_switches_off_the_derivative_terms(tmp_path) -> None:
    out = tmp_path / "mf"
    res = _run("train", "--env", "euclidean", "--out", str(out), "--timesteps", "2000",
               "--quiet", "--model-free", "--set", "path_energy_weight=0")
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "config.json").read_text())
    assert doc["model_free"] is True and doc["uses_derivative_of_C"] == []
    res = _run("train", "--env", "euclidean", "--out", str(tmp_path / "x"), "--paper",
               "--model-free")
    assert res.exit_code == 2 and "one of --paper, --model-free" in res.output
    # the car-like defaults differentiate C (path energy); Matsumoto's are model-free
    assert learn.default_config("carlike").model_free is False
    assert learn.default_config("matsumoto").model_free is True
