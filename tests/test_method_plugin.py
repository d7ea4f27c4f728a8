"""A learning method written in one file outside the package (tests/plugins/toy_method.py)
trains, resumes, evaluates and sweeps through the CLI like a built-in method."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import finsler
import learn
from learn import registry
from learn.config import MetricConfig
from learn.storage import read_metrics
from validation.cli import app

PLUGIN = Path(__file__).resolve().parent / "plugins" / "toy_method.py"
ENV = "euclidean"  # task depth 4: 16 segments; C is the exact length of a segment
#: Evaluations of C per toy iteration, by hand: 4 directions x (+, -) x 32 pairs x 2**4.
PER_ITERATION = 4 * 2 * 32 * 16
runner = CliRunner()


def _cli(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def _train(out: Path, timesteps: int, *more: str):
    return _cli("train", "--env", ENV, "--out", out, "--method", "toy", "--method-module",
                PLUGIN, "--timesteps", timesteps, "--quiet", *more)


def _rows(rows: list[dict], clock: bool = False) -> str:
    """Metrics rows as comparable text (NaN equals NaN), without the clock's columns."""
    drop = () if clock else ("wall_seconds", "evaluations_per_second")
    return json.dumps([{k: v for k, v in r.items() if k not in drop} for r in rows])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A run of 2 iterations resumed to 4, and a run of 4 iterations straight away."""
    root = tmp_path_factory.mktemp("plugin")
    path_before, threads = list(sys.path), torch.get_num_threads()
    torch.set_num_threads(1)  # tiny networks: threads only contend on a shared machine
    try:
        res = _train(root / "run", 2 * PER_ITERATION, "--set", "eval_every=1")
        assert res.exit_code == 0, res.output
        part = read_metrics(root / "run" / "metrics.csv")
        shutil.copytree(root / "run", root / "part")
        res = _train(root / "run", 4 * PER_ITERATION, "--resume")
        assert res.exit_code == 0, res.output
        res = _train(root / "straight", 4 * PER_ITERATION, "--set", "eval_every=1")
        assert res.exit_code == 0, res.output
        yield {"root": root, "part": part}
    finally:  # the toy method is not left registered for the other tests of this process
        if "toy" in registry.list_methods():
            registry.unregister_method("toy")
        sys.modules.pop("toy_method", None)
        sys.path[:] = path_before
        torch.set_num_threads(threads)


def test_the_run_directory_records_the_method_and_its_module(runs) -> None:
    part = runs["root"] / "part"
    assert {p.name for p in part.iterdir()} >= {
        "config.json", "metrics.csv", "checkpoint_latest.pt", "checkpoint_best.pt",
        "result.json"}
    doc = json.loads((part / "config.json").read_text())
    assert doc["config"]["method"] == "toy" and doc["config"]["env"] == ENV
    assert doc["method_module"] == "toy_method"
    assert doc["method_file"] == str(PLUGIN)
    assert doc["model_free"] is True and doc["task"]["segments"] == 16
    rows = runs["part"]
    # a row at iteration 0, one per iteration; every evaluation of C counted (by hand)
    assert [r["iteration"] for r in rows] == [0, 1, 2]
    assert [r["timesteps"] for r in rows] == [0, PER_ITERATION, 2 * PER_ITERATION]
    assert all(r["timesteps_paper"] == r["timesteps"] for r in rows)
    assert all(r["timesteps_derivative"] == 0 for r in rows)
    assert all(0.0 <= r["success_rate"] <= 1.0 for r in rows)
    result = json.loads((part / "result.json").read_text())
    assert result["stopped_by"] == "timesteps"


def test_resume_continues_the_run_exactly(runs) -> None:
    rows = read_metrics(runs["root"] / "run" / "metrics.csv")
    part = runs["part"]
    assert _rows(rows[: len(part)], clock=True) == _rows(part, clock=True)  # kept as written
    assert [r["timesteps"] for r in rows[len(part):]] == [3 * PER_ITERATION,
                                                          4 * PER_ITERATION]
    # resumed = trained straight to the larger budget (same seed, same result)
    straight = read_metrics(runs["root"] / "straight" / "metrics.csv")
    assert _rows(rows) == _rows(straight)
    # the toy learns: its paths are shorter than those of its random initial weights
    assert rows[-1]["mean_length"] < rows[0]["mean_length"]


def test_resume_with_other_settings_is_refused(runs, tmp_path) -> None:
    shutil.copytree(runs["root"] / "part", tmp_path / "r")
    res = _train(tmp_path / "r", 4 * PER_ITERATION, "--resume", "--set", "lr=0.5")
    assert res.exit_code == 2
    assert "cannot resume with different settings: lr" in res.output


def test_evaluate_a_plugin_run(runs) -> None:
    run = runs["root"] / "run"
    res = _cli("evaluate", "--run", run, "--json", "--method-module", PLUGIN)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["checkpoint"] == "checkpoint_best.pt" and doc["env"] == ENV
    assert doc["depth"] == 4 and doc["eps"] == finsler.get_metric(ENV).task.eps
    pairs = finsler.default_pairs(finsler.get_metric(ENV))
    length = np.array([p["length"] for p in doc["per_pair"]])
    ratio = length / np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1)  # exact distance
    assert len(ratio) == 100 and np.all(np.isfinite(ratio))
    assert ratio.min() >= 1 - 1e-9  # no path is shorter than the straight line
    assert 0.0 <= doc["success_rate"] <= 1.0
    assert doc["success_rate"] == np.mean([p["success"] for p in doc["per_pair"]])
    # the CLI's figures are the Python API's, and the run's latest checkpoint loads too
    policy = learn.load_policy(run, checkpoint="latest")
    assert type(policy).__name__ == "ToyPolicy" and policy.checkpoint == "checkpoint_latest.pt"
    ev = learn.load_policy(run).evaluate()
    assert ev.mean_length == pytest.approx(length.mean(), rel=1e-12)
    res = _cli("evaluate", "--run", run, "--depth", "2", "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["depth"] == 2


def test_sweep_a_plugin_method(runs, tmp_path) -> None:
    out = tmp_path / "sweep"
    args = ("sweep", "--envs", ENV, "--methods", "toy", "--seeds", "2", "--out", out,
            "--timesteps", 2 * PER_ITERATION, "--set", "eval_every=1", "--workers", "1",
            "--quiet", "--json", "--method-module", PLUGIN)
    res = _cli(*args)
    assert res.exit_code == 0, res.output
    plan = json.loads((out / "sweep.json").read_text())
    assert plan["variants"] == ["toy"] and plan["modules"] == ["toy_method"]
    assert [r["status"] for r in plan["runs"]] == ["finished", "finished"]
    for seed in (0, 1):
        cfg = json.loads((out / ENV / "toy" / f"seed-{seed}" / "config.json").read_text())
        assert cfg["config"]["seed"] == seed and cfg["config"]["method"] == "toy"
    # seed 0 in a worker process = the run trained here with the same settings
    rows = read_metrics(out / ENV / "toy" / "seed-0" / "metrics.csv")
    assert _rows(rows) == _rows(runs["part"])
    assert read_metrics(out / ENV / "toy" / "seed-1" / "metrics.csv") != rows
    res = _cli(*args)  # run again: nothing to do
    assert res.exit_code == 0, res.output
    assert {r["action"] for r in json.loads(res.output)} == {"skipped"}


def test_a_plugin_policy_warm_starts_an_exact_solve(runs) -> None:
    run = runs["root"] / "run"
    res = _cli("solve", "--metric", ENV, "--start", "0.1,0.2", "--goal", "-0.5,0.3",
               "--warm-start", run, "--method-module", PLUGIN, "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # (stderr: --warm-start's deprecation warning)
    # the learned path is one more start beside the global seeds (issue 47)
    assert doc["warm_start"]["policy"] == str(run) and doc["warm_start"]["global_seeds"]
    assert doc["results"][0]["status"] == "success"
    assert doc["results"][0]["length"] == pytest.approx(np.hypot(0.6, 0.1), rel=1e-9)


def _one_line_error(res, *parts: str) -> None:
    assert res.exit_code == 2, res.output
    text = res.output.strip()
    assert text.startswith("error: ") and "\n" not in text, text
    for part in parts:
        assert part in text, text


def test_bad_method_modules_and_names(runs, tmp_path) -> None:
    empty = tmp_path / "registers_nothing.py"
    empty.write_text("X = 1\n")
    res = _cli("train", "--env", ENV, "--out", tmp_path / "a", "--method", "toy",
               "--method-module", empty, "--quiet")
    _one_line_error(res, "registers_nothing.py: registers no learning method")
    res = _train(tmp_path / "b", PER_ITERATION, "--method", "toyy")
    _one_line_error(res, "unknown method 'toyy' (did you mean 'toy'?)")
    res = _cli("sweep", "--envs", ENV, "--methods", "nope", "--seeds", "1", "--out",
               tmp_path / "c", "--method-module", PLUGIN)
    _one_line_error(res, "unknown variant 'nope'", "--method-module FILE.py")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_run_whose_module_cannot_be_imported_names_the_file(runs, tmp_path) -> None:
    run = tmp_path / "moved"
    shutil.copytree(runs["root"] / "part", run)
    doc = json.loads((run / "config.json").read_text())
    doc["config"]["method"] = "toy-elsewhere"  # a method of a module not importable here
    doc["method_module"] = "toy_method_elsewhere"
    (run / "config.json").write_text(json.dumps(doc))
    res = _cli("evaluate", "--run", run)
    _one_line_error(res, "cannot import module 'toy_method_elsewhere' of the run's method "
                    f"'toy-elsewhere'; pass --method-module {PLUGIN}")


def test_the_readme_commands_run(runs, tmp_path) -> None:
    """The README's commands of "Adding a learning method", with budgets 1/12 of its."""
    readme = (PLUGIN.parents[2] / "README.md").read_text()
    section = readme.split("### Adding a learning method", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```bash\n(.*?)```", section, flags=re.S).group(1)
    lines = block.strip().splitlines()
    assert lines[0] == "M=tests/plugins/toy_method.py"
    commands = [line.replace("$M", str(PLUGIN)).replace("runs/", f"{tmp_path}/")
                for line in lines[1:]]
    assert [c.split()[1] for c in commands] == ["train", "train", "evaluate", "sweep"]
    for command in commands:
        args = re.sub(r"--timesteps (\d+)", lambda m: f"--timesteps {int(m[1]) // 12}",
                      command).split()[1:]
        res = _cli(*args, *(["--quiet"] if args[0] in ("train", "sweep") else []))
        assert res.exit_code == 0, (command, res.output)
    assert learn.load_policy(tmp_path / "toy").metric.name == "matsumoto"
    rows = read_metrics(tmp_path / "toy" / "metrics.csv")
    assert rows[-1]["timesteps"] >= 400000 // 12  # resumed to the second budget


@pytest.mark.parametrize("as_text", [False, True])
def test_a_method_config_checks_the_field_types_it_knows(as_text) -> None:
    """A user config's fields are type-checked whether its annotations are types or text
    (``from __future__ import annotations``); other field types are left to the config."""
    spec = [("env", str, "euclidean"), ("metric_params", dict[str, Any] | None, None),
            ("metric_class", str | None, None), ("seed", int, 0),
            ("width", tuple[int, ...], (4,)), ("weights", list[float], None)]
    fields = [(name, (t.__name__ if isinstance(t, type) else str(t)) if as_text else t,
               dataclasses.field(default=d)) for name, t, d in spec]
    cls = dataclasses.make_dataclass("UserConfig", fields, bases=(MetricConfig,),
                                     namespace={"__post_init__": MetricConfig._check_types})
    assert cls(weights=[0.5]).metric_params == {"n": 2}
    with pytest.raises(finsler.InputError, match="config field seed must be int, got 'x'"):
        cls(seed="x")
    with pytest.raises(finsler.InputError, match=r"width must be tuple\[int, \.\.\.\]"):
        cls(width=(1, "a"))
    with pytest.raises(finsler.InputError, match="metric_class must be str"):
        cls(metric_class=3)
