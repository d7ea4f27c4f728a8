"""Any metric (issue 11, part 2): a run records its metric's parameters (and a user
metric's class), trains, reloads, resumes and reports with them; mismatches are refused."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import casadi as ca
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import finsler
import learn
from finsler import Disk, InputError, Metric, Task
from learn import TrainConfig, Trainer
from learn.run_config import resolve_metric
from learn.storage import CONFIG_FILE, LATEST_FILE, RESULT_FILE, read_json
from validation.cli import app
from validation.cli.common import parse_metric_params

torch.set_num_threads(1)
ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Wavy(Metric):
    """The README's example: F(x, v) = (1 + a sin(3 x_0)^2) |v| on the unit disk."""

    a: float = 0.5
    name: ClassVar[str] = "wavy"
    task: ClassVar[Task] = Task(depth=5, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + self.a * ca.sin(3 * x[0]) ** 2) * ca.sqrt(ca.dot(v, v))


THIS_CLASS = f"{Wavy.__module__}:{Wavy.__qualname__}"


@pytest.fixture(autouse=True)
def _registry():
    """Register Wavy for the test; restore the registry afterwards (tests register others)."""
    saved = dict(finsler.registry._REGISTRY)
    finsler.register_metric(Wavy)
    yield
    finsler.registry._REGISTRY.clear()
    finsler.registry._REGISTRY.update(saved)


def _wavy_cost(a: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """C(x, y) of the wavy metric, written by hand (independent of CasADi)."""
    return (1 + a * np.sin(3 * x[:, 0]) ** 2) * np.linalg.norm(y - x, axis=1)


def _tiny(**over: object) -> TrainConfig:
    base = dict(metric_params={"a": 0.2}, timesteps=6_000, depth=3, hidden=(16, 16),
                collection_size=256, minibatch_size=128, epochs=1, eval_every=2,
                eval_pairs=8, path_energy_weight=0.0)
    base.update(over)
    return learn.default_config("wavy", **base)


# ----------------------------------------------------------------------------------------
# validation of the parameters
# ----------------------------------------------------------------------------------------
def test_params_are_completed_and_checked() -> None:
    full, cls = resolve_metric("wavy", {"a": 1})
    assert full == {"a": 1.0} and isinstance(full["a"], float)
    assert cls == THIS_CLASS
    assert resolve_metric("matsumoto", None) == ({"height": 1.0, "radius": 1.0}, None)
    assert resolve_metric("carlike", {"r_min": 0.25})[0] == {
        "c_p": 100.0, "r_min": 0.25, "radius": 1.0}
    with pytest.raises(InputError, match=r"no parameter 'b'.*a \(float\)"):
        resolve_metric("wavy", {"b": 0.2})
    with pytest.raises(InputError, match="must be float"):
        resolve_metric("wavy", {"a": "big"})
    with pytest.raises(InputError, match="must be float"):
        resolve_metric("wavy", {"a": True})
    with pytest.raises(InputError, match="must be float"):
        resolve_metric("wavy", {"a": float("nan")})
    with pytest.raises(InputError, match="must be int"):
        resolve_metric("euclidean", {"n": 2.5})
    with pytest.raises(InputError, match="positive"):  # the metric's own check
        resolve_metric("matsumoto", {"height": -1.0})
    with pytest.raises(InputError, match="dict"):
        TrainConfig(env="wavy", metric_params=[0.2])  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"is class other\.module:Wavy"):
        TrainConfig(env="wavy", metric_class="other.module:Wavy")


def test_cli_param_parsing() -> None:
    assert parse_metric_params(None) is None
    assert parse_metric_params(["a=0.2", "n=3", "s=text"]) == {"a": 0.2, "n": 3, "s": "text"}
    for bad in (["a"], ["=1"], ["a="]):
        with pytest.raises(InputError, match="NAME=VALUE"):
            parse_metric_params(bad)
    with pytest.raises(InputError, match="twice"):
        parse_metric_params(["a=1", "a=2"])


def test_old_configs_without_the_field_load_with_the_defaults(tmp_path: Path) -> None:
    cfg = TrainConfig.from_dict({"env": "matsumoto"})
    assert cfg.metric_params == {"height": 1.0, "radius": 1.0} and cfg.metric_class is None
    # policies written before the field existed: the shipped ones of that time and the
    # replaced ones kept for the benchmarks
    folders = [ROOT / "learn" / "policies" / env for env in learn.shipped_policies()]
    folders += sorted(p for p in (ROOT / "benchmarks" / "previous_policies").iterdir()
                      if p.is_dir())
    old = [f for f in folders if "metric_params" not in read_json(f / CONFIG_FILE)["config"]]
    # every car-like policy kept is newer: the shipped one with the fields taken out of
    # its config stands for the old car-like files
    stripped = tmp_path / "carlike"
    shutil.copytree(ROOT / "learn" / "policies" / "carlike", stripped)
    doc = read_json(stripped / CONFIG_FILE)
    del doc["config"]["metric_params"], doc["config"]["metric_class"]
    (stripped / CONFIG_FILE).write_text(json.dumps(doc))
    old.append(stripped)
    assert {f.name for f in old} >= {"matsumoto", "carlike", "panda-pole"}
    for folder in old:
        pol = learn.load_policy(folder)
        assert pol.metric == finsler.get_metric(folder.name)
        assert pol.config.metric_params == TrainConfig.from_dict(
            {"env": folder.name}).metric_params
    with pytest.raises(InputError, match=r"height=1.0 \(given 2.0\)"):
        learn.load_any_policy("matsumoto", metric_params={"height": 2.0})


# ----------------------------------------------------------------------------------------
# a tiny run on a non-default parameter: train, reload, resume, refuse a mismatch
# ----------------------------------------------------------------------------------------
def test_tiny_run_on_a_nondefault_parameter(tmp_path: Path, monkeypatch) -> None:
    cfg = _tiny()
    full = learn.train_run(cfg, tmp_path / "full", progress=False)
    doc = read_json(tmp_path / "full" / CONFIG_FILE)
    assert doc["config"]["metric_params"] == {"a": 0.2}
    assert doc["config"]["metric_class"] == THIS_CLASS
    assert doc["metric"]["params"] == {"a": 0.2}

    # reloaded with the run's parameter: its metric's values are those of a = 0.2
    pol = learn.load_policy(tmp_path / "full", metric_params={"a": 0.2})
    rng = np.random.default_rng(5)
    x, y = pol.metric.domain.sample(50, rng), pol.metric.domain.sample(50, rng)
    assert np.allclose(pol.metric.cost(x, y), _wavy_cost(0.2, x, y), rtol=1e-13)
    assert np.allclose(pol.metric.cost(x, y), finsler.get_metric("wavy", a=0.2).cost(x, y),
                       rtol=0, atol=0)
    assert not np.allclose(pol.metric.cost(x, y), finsler.get_metric("wavy").cost(x, y))
    # the evaluation is on that metric: lengths recomputed by hand from the paths
    pairs = finsler.default_pairs(pol.metric, 10)
    res = pol.evaluate(pairs)
    paths = pol.generate(pairs[:, 0], pairs[:, 1])
    by_hand = np.array([_wavy_cost(0.2, p[:-1], p[1:]).sum() for p in paths])
    assert np.allclose(res.length, by_hand, rtol=1e-12)
    with pytest.raises(InputError, match=r"a=0.2 \(given 0.3\)"):
        learn.load_any_policy(tmp_path / "full", metric_params={"a": 0.3})

    # a crash between checkpoints, then resume: same weights as the uninterrupted run
    calls = [0]
    real_update = Trainer.update

    def crashing_update(self, *a):
        calls[0] += 1
        if calls[0] == 3:
            raise RuntimeError("simulated crash")
        return real_update(self, *a)

    monkeypatch.setattr(Trainer, "update", crashing_update)
    with pytest.raises(RuntimeError, match="simulated crash"):
        learn.train_run(cfg, tmp_path / "crash", progress=False)
    monkeypatch.setattr(Trainer, "update", real_update)
    assert not (tmp_path / "crash" / RESULT_FILE).exists()
    with pytest.raises(InputError, match=r"metric_params \(\{'a': 0.2\} in the run, "
                                         r"\{'a': 0.3\} given\)"):
        learn.train_run(_tiny(metric_params={"a": 0.3}), tmp_path / "crash", resume=True,
                        progress=False)
    resumed = learn.train_run(cfg, tmp_path / "crash", resume=True, progress=False)
    assert resumed.timesteps == full.timesteps
    a = learn.storage.load_checkpoint(tmp_path / "full" / LATEST_FILE)
    b = learn.storage.load_checkpoint(tmp_path / "crash" / LATEST_FILE)
    assert b["config"]["metric_params"] == {"a": 0.2}
    for k in a["actor"]:
        assert torch.equal(a["actor"][k], b["actor"][k]), k


def test_run_reloads_in_a_fresh_process_by_importing_the_class(tmp_path: Path) -> None:
    learn.train_run(_tiny(timesteps=1_500), tmp_path / "r", progress=False)
    code = ("import sys, numpy as np, finsler, learn\n"
            "assert 'wavy' not in finsler.list_metrics()\n"
            f"p = learn.load_policy({str(tmp_path / 'r')!r})\n"
            "x = np.array([[0.3, 0.1]]); y = np.array([[-0.2, 0.4]])\n"
            "print(type(p.metric).__module__, p.metric.a, float(p.metric.cost(x, y)[0]))\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    module, a, c = out.stdout.split()
    assert module == Wavy.__module__ and float(a) == 0.2
    x, y = np.array([[0.3, 0.1]]), np.array([[-0.2, 0.4]])
    assert float(c) == pytest.approx(_wavy_cost(0.2, x, y)[0], rel=1e-14)
    # without the module on the path the error says what to do
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={k: v for k, v in env.items() if k != "PYTHONPATH"},
                         timeout=120, cwd=tmp_path)
    assert out.returncode != 0 and "--metric-module" in out.stderr


# ----------------------------------------------------------------------------------------
# the command line: train, evaluate, report, resume with --metric-param
# ----------------------------------------------------------------------------------------
README_WAVY = '''
from dataclasses import dataclass
from typing import ClassVar
import casadi as ca
from finsler import Disk, Metric, Task, register_metric

@register_metric
@dataclass(frozen=True)
class Wavy(Metric):
    a: float = 0.5
    name: ClassVar[str] = "wavy"
    task: ClassVar[Task] = Task(depth=5, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Disk(radius=1.0))
    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + self.a * ca.sin(3 * x[0]) ** 2) * ca.sqrt(ca.dot(v, v))
'''


@pytest.fixture()
def _clean_imports(monkeypatch):
    """--metric-module puts the file's folder on sys.path and imports it: undo both."""
    monkeypatch.setattr(sys, "path", list(sys.path))
    yield
    sys.modules.pop("user_wavy_metric", None)


@pytest.mark.usefixtures("_clean_imports")
def test_cli_train_evaluate_report_with_metric_params(tmp_path: Path) -> None:
    finsler.registry._REGISTRY.pop("wavy")  # the CLI imports it from the user's file
    mod = tmp_path / "user_wavy_metric.py"
    mod.write_text(README_WAVY)
    r = CliRunner()
    run = tmp_path / "run"
    small = ["--set", "depth=3", "--set", "hidden=[16,16]", "--set", "collection_size=256",
             "--set", "minibatch_size=128", "--set", "epochs=1", "--set", "eval_every=2",
             "--set", "eval_pairs=8", "--set", "path_energy_weight=0"]
    res = r.invoke(app, ["train", "--env", "wavy", "--out", str(run), "--quiet",
                         "--timesteps", "3000", "--metric-param", "b=0.2",
                         "--metric-module", str(mod), *small])
    assert res.exit_code == 2 and "no parameter 'b'" in res.output and "a (float)" in res.output
    res = r.invoke(app, ["train", "--env", "wavy", "--out", str(run), "--quiet",
                         "--timesteps", "3000", "--metric-param", "a=0.2",
                         "--metric-module", str(mod), *small])
    assert res.exit_code == 0, res.output
    cfg = read_json(run / CONFIG_FILE)["config"]
    assert cfg["metric_params"] == {"a": 0.2}
    assert cfg["metric_class"] == "user_wavy_metric:Wavy"

    res = r.invoke(app, ["evaluate", "--run", str(run), "--json", "--metric-param", "a=0.2"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["env"] == "wavy" and out["metric_params"] == {"a": 0.2}
    pol = learn.load_policy(run)
    assert out["success_rate"] == pol.evaluate().success_rate
    res = r.invoke(app, ["evaluate", "--run", str(run), "--metric-param", "a=0.3"])
    assert res.exit_code == 2 and "a=0.2 (given 0.3)" in res.output
    res = r.invoke(app, ["train", "--env", "wavy", "--out", str(run), "--resume", "--quiet",
                         "--metric-param", "a=0.3"])
    assert res.exit_code == 2 and "metric_params" in res.output

    pairs = tmp_path / "pairs.npy"
    np.save(pairs, finsler.default_pairs(pol.metric, 3))
    res = r.invoke(app, ["report", "--run", str(run), "--out", str(tmp_path / "rep"),
                         "--pairs", str(pairs), "--no-continuum", "--workers", "1",
                         "--no-progress", "--metric-param", "a=0.2"])
    assert res.exit_code == 0, res.output
    doc = read_json(tmp_path / "rep" / "report.json")
    assert doc["metric"] == "wavy" and doc["metric_params"] == {"a": 0.2}
    assert "paths.png" in doc["figures"]
    assert "a = 0.2" in (tmp_path / "rep" / "report.md").read_text()
    # the report's learned lengths are sums of the a = 0.2 costs (not the default's)
    paths = pol.generate(np.load(pairs)[:, 0], np.load(pairs)[:, 1])
    want = np.mean([_wavy_cost(0.2, p[:-1], p[1:]).sum() for p in paths])
    assert doc["mean_length"]["learned"] == pytest.approx(want, rel=1e-10)


def test_report_picks_figures_by_what_the_metric_is(tmp_path: Path) -> None:
    from validation import StraightLine, build_report

    @dataclass(frozen=True)
    class Boat(Metric):
        """A user 3-D pose metric (x, y, heading) that is not car-like by name."""

        name: ClassVar[str] = "boat"
        task: ClassVar[Task] = Task(depth=3, eps=0.5)
        domain = property(lambda self: finsler.Box((-1, -1, -3), (1, 1, 3),
                                                   names=("x", "y", "theta")))

        def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
            return ca.sqrt(ca.dot(v, v))

    @dataclass(frozen=True)
    class Cube(Metric):
        name: ClassVar[str] = "cube"
        task: ClassVar[Task] = Task(depth=3, eps=0.5)
        domain = property(lambda self: finsler.Box((-1, -1, -1), (1, 1, 1)))

        def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
            return (1 + 0.1 * x[2] ** 2) * ca.sqrt(ca.dot(v, v))

    for cls, want in ((Boat, "carlike_headings.png"), (Cube, "coordinates.png"),
                      (Wavy, "paths.png")):
        finsler.register_metric(cls)
        m = finsler.get_metric(cls.name)
        doc = build_report(cls.name, tmp_path / cls.name, pairs=finsler.default_pairs(m, 2),
                           policy=StraightLine(m), workers=1, progress=False,
                           continuum=False)
        shapes = {"paths.png", "carlike_headings.png", "panda_motion.png", "coordinates.png"}
        assert shapes & set(doc["figures"]) == {want}, doc["figures"]
        assert (tmp_path / cls.name / want).stat().st_size > 10_000


def test_sweep_passes_the_metric_to_its_workers() -> None:
    from validation.cli.sweep import metric_overrides

    assert metric_overrides(["matsumoto"], None) == {}
    assert metric_overrides(["matsumoto", "carlike"], {"radius": 0.9}) == {
        "metric_params": {"radius": 0.9}}
    # a user metric: its class goes to the (spawned) workers, which import it
    assert metric_overrides(["wavy"], {"a": 0.2}) == {"metric_params": {"a": 0.2},
                                                      "metric_class": THIS_CLASS}
    with pytest.raises(InputError, match="alone"):
        metric_overrides(["wavy", "matsumoto"], None)
    res = CliRunner().invoke(app, ["train", "--env", "wavy", "--out", "/nonexistent/x",
                                   "--set", 'metric_params={"a": 0.2}'])
    assert res.exit_code == 2 and "use --metric-param" in res.output


@pytest.mark.parametrize("variant", ["seq", "pg"])
def test_baselines_train_and_reload_on_the_parameters(tmp_path: Path, variant: str) -> None:
    """The paper's baselines go through the same metric fields (learn.runs entry points)."""
    small = {"seq": dict(timesteps=600, eval_every=300, eval_pairs=4, n_envs=2, n_steps=32,
                         batch_size=32, n_epochs=1, depth=3),
             "pg": dict(depth=2, cycles_first=1, cycles_other=1, pairs_per_cycle=2,
                        samples_per_pair=2, eval_every=1, eval_pairs=4)}[variant]
    cfg = learn.make_config("wavy", variant, metric_params={"a": 0.2}, **small)
    assert cfg.metric_params == {"a": 0.2} and cfg.metric_class == THIS_CLASS
    learn.train_run(cfg, tmp_path / "r", progress=False)
    assert read_json(tmp_path / "r" / CONFIG_FILE)["metric"]["params"] == {"a": 0.2}
    pol = learn.load_any_policy(tmp_path / "r", metric_params={"a": 0.2})
    x, y = np.array([[0.3, 0.1]]), np.array([[-0.2, 0.4]])
    assert pol.metric.cost(x, y)[0] == pytest.approx(_wavy_cost(0.2, x, y)[0], rel=1e-14)
    with pytest.raises(InputError, match=r"a=0.2 \(given 0.5\)"):
        learn.load_any_policy(tmp_path / "r", metric_params={})  # {} = the defaults
    with pytest.raises(InputError, match="metric_params"):
        learn.train_run(cfg.replace(metric_params={"a": 0.3}), tmp_path / "r", resume=True,
                        progress=False)


def test_figure_hooks_follow_what_the_metric_is() -> None:
    from validation import figures as fg

    m = finsler.get_metric("matsumoto", height=2.0)
    p = np.array([[0.3, 0.4], [0.0, 0.0]])
    assert np.allclose(fg.height_map(m)(p), [-2.0 * 0.25, 0.0])  # h = -height |p|^2
    assert fg.height_map(finsler.get_metric("wavy")) is None

    @dataclass(frozen=True)
    class Hill(Wavy):  # a user hook, under another name
        name: ClassVar[str] = "hill"

        def height_map(self, pts: np.ndarray) -> np.ndarray:
            return np.exp(-np.sum(pts**2, axis=1))

    assert np.allclose(fg.height_map(Hill())(p), np.exp(-np.array([0.25, 0.0])))
    assert fg.is_planar_pose(finsler.get_metric("carlike"))
    assert not fg.is_planar_pose(finsler.get_metric("matsumoto"))
    assert fg.has_kinematics(finsler.get_metric("panda-pole"))
    assert not fg.has_kinematics(finsler.get_metric("carlike"))


def test_exact_commands_take_the_metric_parameters() -> None:
    # cost, solve, certify, exp and log build the metric with --metric-param: their numbers
    # are the Python API's on get_metric(name, **params), not the defaults'
    cli = CliRunner()
    s, g = "0.1,0.2", "0.6,-0.3"
    steep = finsler.get_metric("matsumoto", height=2.0)
    res = cli.invoke(app, ["cost", "--metric", "matsumoto", "--metric-param", "height=2",
                           "--start", s, "--goal", g, "--json"])
    assert res.exit_code == 0, res.output
    a, b = np.array([0.1, 0.2]), np.array([0.6, -0.3])
    want = float(np.asarray(steep.cost(a, b)).reshape(-1)[0])
    default = float(np.asarray(finsler.get_metric("matsumoto").cost(a, b)).reshape(-1)[0])
    got = json.loads(res.output)
    assert abs(got["cost"] - want) < 1e-12 and abs(want - default) > 1e-2
    res = cli.invoke(app, ["solve", "--metric", "matsumoto", "--metric-param", "height=2",
                           "--start", s, "--goal", g, "--segments", "16", "--json"])
    assert res.exit_code == 0, res.output
    import solvers

    ref = solvers.solve_geodesic(steep, np.array([0.1, 0.2]), np.array([0.6, -0.3]), 16)
    assert abs(json.loads(res.output)["results"][0]["energy"] - ref.energy) < 1e-6 * ref.energy
    # Poincare disk of radius 0.5 (curvature unchanged): a point at 0.6 is outside it
    res = cli.invoke(app, ["exp", "--metric", "poincare", "--metric-param", "radius=0.5",
                           "--start", "0.6,0", "--velocity", "0.1,0"])
    assert res.exit_code == 2 and "outside" in res.output
    res = cli.invoke(app, ["log", "--metric", "matsumoto", "--metric-param", "height=x",
                           "--start", s, "--goal", g])
    assert res.exit_code == 2 and "height" in res.output
