"""A learning method written in one file (the shipped example learn/examples/toy_method.py,
given by its path as a user's copy would be, and by its module name) trains, resumes,
evaluates and sweeps through the CLI like a built-in method; it declares no run field
again and every registered method's policy has the policy protocol."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import finsler
import learn
from learn import RunConfig, registry
from learn.run_config import RUN_FIELDS
from learn.storage import read_metrics
from validation.cli import app

ROOT = Path(__file__).resolve().parents[2]
#: The shipped example, given by its path (imported as module ``toy_method``, as a copy
#: of it in a user's folder would be).
PLUGIN = ROOT / "learn" / "examples" / "toy_method.py"
GUIDE = ROOT / "docs" / "guides" / "methods.md"
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
        sys.modules.pop("learn.examples.toy_method", None)
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


def _forget_example() -> None:
    """Unregister the method "toy" and forget the shipped example's module (the state of a
    new process)."""
    if "toy" in registry.list_methods():
        registry.unregister_method("toy")
    sys.modules.pop("learn.examples.toy_method", None)


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


def test_the_guide_commands_run(runs, tmp_path) -> None:
    """The guide's commands (docs/guides/methods.md), with budgets 1/12 of its: the
    shipped example by its module name, as an installed package has it."""
    _forget_example()  # as in a new shell: whatever an earlier test imported or registered
    block = re.search(r"```bash\n(.*?)```", GUIDE.read_text(), flags=re.S).group(1)
    lines = block.strip().splitlines()
    assert lines[0] == "M=learn.examples.toy_method"
    commands = [line.replace("$M", "learn.examples.toy_method")
                .replace("runs/", f"{tmp_path}/") for line in lines[1:]]
    assert [c.split()[1] for c in commands] == ["train", "train", "evaluate", "sweep"]
    for command in commands:
        args = re.sub(r"--timesteps (\d+)", lambda m: f"--timesteps {int(m[1]) // 12}",
                      command).split()[1:]
        res = _cli(*args, *(["--quiet"] if args[0] in ("train", "sweep") else []))
        assert res.exit_code == 0, (command, res.output)
    # the run records the shipped module, so loading it needs no --method-module
    doc = json.loads((tmp_path / "toy" / "config.json").read_text())
    assert doc["method_module"] == "learn.examples.toy_method"
    _forget_example()  # as in a new process: loading the run imports the module
    assert learn.load_policy(tmp_path / "toy").metric.name == "matsumoto"
    rows = read_metrics(tmp_path / "toy" / "metrics.csv")
    assert rows[-1]["timesteps"] >= 400000 // 12  # resumed to the second budget
    assert (tmp_path / "toy-sweep" / "matsumoto" / "toy" / "seed-1" / "result.json").is_file()


def test_the_example_ships_in_the_package() -> None:
    """learn/examples is a package that setuptools' discovery of pyproject.toml finds."""
    import tomllib
    from setuptools import find_packages

    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = find_packages(str(ROOT), include=tool["packages"]["find"]["include"])
    assert "learn.examples" in found and "learn" in found
    assert (ROOT / "learn" / "examples" / "__init__.py").is_file()


def test_no_method_declares_a_run_field_again() -> None:
    """Every registered method's config (and the example's) takes its run fields from
    RunConfig: not one is declared in the method's own class."""
    import inspect

    import learn.examples.toy_method as toy

    configs = {m.config_class for m in map(registry.get_method, registry.list_methods())}
    configs.add(toy.ToyConfig)
    assert len(configs) >= 4
    for cls in configs:
        assert issubclass(cls, RunConfig)
        for klass in cls.__mro__[: cls.__mro__.index(RunConfig)]:
            source = inspect.getsource(klass)
            for name in RUN_FIELDS:  # no annotation "name:" in the class body
                assert not re.search(rf"^    {name}:", source, flags=re.M), (klass, name)
    with pytest.raises(TypeError, match="declares the run field"):
        @dataclasses.dataclass
        class Again(RunConfig):
            seed: int = 3


def test_a_method_config_has_its_defaults_and_the_run_checks() -> None:
    from learn.examples.toy_method import ToyConfig

    cfg = ToyConfig("euclidean")
    assert (cfg.method, cfg.timesteps, cfg.eval_every, cfg.eval_pairs) == ("toy", 20_000, 5,
                                                                          100)
    assert [f.name for f in dataclasses.fields(cfg)][:3] == ["env", "metric_params",
                                                             "metric_class"]
    for field, value in (("minutes", 0.0), ("minutes", float("inf")), ("seed", -1),
                         ("method", "pg"), ("threads", 0), ("eval_pairs", 0),
                         ("depth", 0), ("eps", float("nan")), ("device", "tpu")):
        with pytest.raises(finsler.InputError, match=field):
            ToyConfig("euclidean", **{field: value})
    with pytest.raises(finsler.InputError, match="CPU only"):
        ToyConfig("euclidean", device="cuda")


@pytest.mark.parametrize("as_text", [False, True])
def test_a_method_config_checks_the_field_types_it_knows(as_text) -> None:
    """A user config's fields are type-checked whether its annotations are types or text
    (``from __future__ import annotations``); other field types are left to the config."""
    spec = [("count", int, 0), ("width", tuple[int, ...], (4,)),
            ("weights", list[float], None)]
    fields = [(name, (t.__name__ if isinstance(t, type) else str(t)) if as_text else t,
               dataclasses.field(default=d)) for name, t, d in spec]
    cls = dataclasses.make_dataclass("UserConfig", fields, bases=(RunConfig,), namespace={
        "config_methods": ("user",), "run_defaults": {"env": "euclidean"}})
    cfg = cls(weights=[0.5], width=[3, 2])
    assert cfg.metric_params == {"n": 2} and cfg.width == (3, 2)  # a JSON list: a tuple
    with pytest.raises(finsler.InputError, match="config field seed must be int, got 'x'"):
        cls(seed="x")
    with pytest.raises(finsler.InputError, match="config field count must be int"):
        cls(count=1.5)
    with pytest.raises(finsler.InputError, match=r"width must be tuple\[int, \.\.\.\]"):
        cls(width=(1, "a"))
    with pytest.raises(finsler.InputError, match="metric_class must be str"):
        cls(metric_class=3)


def test_every_registered_method_policy_has_the_protocol(runs, tmp_path) -> None:
    """One tiny run of every registered method (budget 1: the first row and checkpoint
    only, one iteration at most) through the one entry point; its loaded policy is a
    learn.PathPolicy, and a MidpointPolicy exactly where it predicts midpoints."""
    _forget_example()
    import learn.examples.toy_method  # registers "toy" by its module name

    pairs = finsler.default_pairs(finsler.get_metric(ENV))[:3]
    seen = set()
    try:
        for name in registry.list_methods():
            method = registry.get_method(name)
            if method.name in seen:
                continue
            seen.add(method.name)
            cfg = method.default_config(ENV, timesteps=1)
            res = learn.train_run(cfg, tmp_path / method.name, progress=False)
            assert res.iterations <= 1
            pol = method.load_policy(tmp_path / method.name)
            assert isinstance(pol, learn.PathPolicy), method.name
            paths = pol.generate(pairs[:, 0], pairs[:, 1])
            assert paths.shape == (3, 2**pol.depth + 1, 2)
            assert 0.0 <= pol.evaluate(pairs).success_rate <= 1.0
            assert isinstance(pol, learn.MidpointPolicy) == (method.name != "seq")
            if isinstance(pol, learn.MidpointPolicy):
                mid = pol.midpoint(pairs[:, 0], pairs[:, 1])
                assert mid.shape == (3, 2) and np.all(np.isfinite(mid))
    finally:
        _forget_example()
    assert seen >= {"midpoint", "pg", "seq", "toy"}


def test_the_old_entry_points_warn_and_still_work(tmp_path) -> None:
    from learn.pg import train_pg
    from learn.seq import train_seq

    for old in (learn.train, train_pg, train_seq):
        with pytest.warns(DeprecationWarning, match=r"use learn\.train_run\(cfg, out"), \
                pytest.raises(finsler.InputError, match="needs a"):
            old(object(), tmp_path / "x", progress=False)
    with pytest.warns(DeprecationWarning, match="learn.train"):
        res = learn.train(learn.default_config(ENV, timesteps=1), tmp_path / "m",
                          progress=False)
    assert res.iterations == 1


def _learn_imports(module: str) -> set[str]:
    """The learn modules ``module`` imports, directly or through others (read from the
    source: every ``import`` / ``from learn... import``, lazy ones inside functions too)."""
    import ast

    seen, todo = set(), [module]
    while todo:
        name = todo.pop()
        path = ROOT / (name.replace(".", "/") + ".py")
        if name in seen or not path.is_file():
            continue
        seen.add(name)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                todo.append(node.module)
            elif isinstance(node, ast.Import):
                todo += [a.name for a in node.names]
    return {m for m in seen if m.startswith("learn.") and m != module}


def test_the_run_loop_stands_below_every_method() -> None:
    """The generic loop and RunConfig import nothing of a method: not the midpoint
    learner's config, terms, expert iteration or route search."""
    below = {"learn.run_config", "learn.base", "learn.storage", "learn.registry"}
    assert _learn_imports("learn.run_config") == set()
    assert _learn_imports("learn.loop") <= below
    for specific in ("learn.midpoint.config", "learn.midpoint.losses", "learn.midpoint.expert",
                     "learn.midpoint.search"):
        assert specific in _learn_imports("learn.midpoint.trainer")  # the check can fail


@pytest.mark.parametrize("module", ["learn.seq.trainer", "learn.pg.trainer",
                                    "learn.examples.toy_method", "learn.runs", "learn.sweep"])
def test_the_baselines_and_the_core_import_nothing_of_the_midpoint_learner(module) -> None:
    """The baselines, the shipped example and the core stand on the shared core only
    (`learn.loop`, `learn.evaluation`, `learn.tree`, ...), never on `learn.midpoint`."""
    assert _learn_imports(module)
    assert not {m for m in _learn_imports(module) if m.startswith("learn.midpoint")}
