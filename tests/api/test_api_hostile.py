"""The Python API under hostile input: every public entry point refuses what it cannot
take with an `InputError` that names the argument (never a raw numpy, torch or CasADi
error, never a number for an impossible question), as the command line does."""

from __future__ import annotations

import dataclasses
import os
from typing import Any, ClassVar

import casadi as ca
import numpy as np
import pytest

import finsler
import solvers
from finsler import Box, InputError, Metric, Task

BAD_POINTS = [
    pytest.param("0.1,0.15", "str", id="str"),
    pytest.param({"a": 1}, "dict", id="dict"),
    pytest.param(None, "None", id="none"),
    pytest.param(np.array([0.1, 0.15]) + 0.5j, "complex", id="complex"),
    pytest.param(np.array([0.1, "x"], dtype=object), "object", id="object"),
    pytest.param(np.array(["0.1", "0.2"]), "<U3", id="string-array"),
    pytest.param([[0.1, 0.2], [0.3]], "list", id="ragged"),
    pytest.param([True, False], "bool", id="bool"),
]


def _raises_naming(call: Any, *names: str) -> str:
    with pytest.raises(InputError) as err:
        call()
    text = str(err.value)
    for name in names:
        assert name in text, text
    assert "\n" not in text and len(text) < 400, text
    return text


@pytest.fixture(scope="module")
def randers() -> Metric:
    return finsler.get_metric("randers")


@pytest.mark.parametrize("bad, got", BAD_POINTS)
def test_metric_methods_refuse_non_numeric_points(randers: Metric, bad: Any, got: str) -> None:
    good = [-0.15, 0.1]
    _raises_naming(lambda: randers.F(bad, good), "x ", got)
    _raises_naming(lambda: randers.F(good, bad), "v ", got)
    _raises_naming(lambda: randers.cost(bad, good), "x ", got)
    _raises_naming(lambda: randers.cost(good, bad), "y ", got)
    _raises_naming(lambda: randers.segment_length(good, bad), "y ")
    _raises_naming(lambda: randers.segment_length_error(bad, good), "x ")
    _raises_naming(lambda: randers.convexity(bad), "x ")


@pytest.mark.parametrize("bad, got", BAD_POINTS)
def test_solvers_refuse_non_numeric_points(randers: Metric, bad: Any, got: str) -> None:
    good = [0.3, -0.1]
    _raises_naming(lambda: solvers.solve_geodesic(randers, bad, good, segments=4), "start")
    _raises_naming(lambda: solvers.solve_geodesic(randers, good, bad, segments=4), "goal")
    _raises_naming(lambda: solvers.distance(randers, bad, good), "start")
    _raises_naming(lambda: solvers.exp_map(randers, bad, good), "x ")
    _raises_naming(lambda: solvers.exp_map(randers, good, bad), "v ")
    _raises_naming(lambda: solvers.log_map(randers, good, bad), "y ")
    _raises_naming(lambda: solvers.certify("poincare", bad, good), "start")


def test_complex_input_is_refused_not_cast(randers: Metric) -> None:
    z = np.array([-0.2, 0.3]) + 0.5j
    _raises_naming(lambda: solvers.solve_geodesic("randers", z, [0.3, -0.1], segments=4),
                   "start", "complex")
    _raises_naming(lambda: randers.segment_length_error(z, [0.3, -0.1]), "x ", "complex")


def test_pairs_and_paths(randers: Metric) -> None:
    _raises_naming(lambda: solvers.solve_batch("randers", "pairs.npy"), "pairs", "str")
    _raises_naming(lambda: solvers.solve_batch("randers", np.zeros((2, 2, 2)) + 1j), "pairs")
    _raises_naming(lambda: randers.path_costs("abc"), "paths")
    # lists are array-likes: a path as nested lists has its costs
    got = randers.path_costs([[[0.1, 0.2], [-0.3, 0.1]]])
    assert got.shape == (1, 1) and np.isfinite(got).all()
    # one point against no points: no lengths, as cost gives none
    assert randers.segment_length([0.1, 0.15], np.zeros((0, 2))).shape == (0,)
    assert randers.cost([0.1, 0.15], np.zeros((0, 2))).shape == (0,)


@pytest.mark.parametrize("n", [-3, 0, 2.5, "x", True, 10**7])
def test_convexity_directions_are_checked(randers: Metric, n: Any) -> None:
    _raises_naming(lambda: randers.convexity([[0.1, 0.1]], n_directions=n), "n_directions")


def test_tol_below_the_rounding_floor_is_refused() -> None:
    _raises_naming(lambda: solvers.solve_geodesic("randers", [-0.2, 0.3], [0.3, -0.1],
                                                  segments=4, tol=1e-300), "tol")
    _raises_naming(lambda: solvers.solve_geodesic("randers", [-0.2, 0.3], [0.3, -0.1],
                                                  segments=4, tol="x"), "tol")


@pytest.mark.parametrize("opts, name", [
    ({"segments": "4"}, "segments"), ({"segments": 10**9}, "segments"),
    ({"initial": 5}, "initial"), ({"global_seeds": "no"}, "global_seeds"),
])
def test_solve_geodesic_options(opts: dict, name: str) -> None:
    _raises_naming(lambda: solvers.solve_geodesic("randers", [-0.2, 0.3], [0.3, -0.1], **opts),
                   name)


@pytest.mark.parametrize("opts, name", [
    ({"rtol": 1j}, "rtol"), ({"rtol": "x"}, "rtol"), ({"degrees": 5}, "degrees"),
    ({"degrees": (8, 10**6)}, "degrees"),
])
def test_distance_options(opts: dict, name: str) -> None:
    _raises_naming(lambda: solvers.distance("randers", [-0.2, 0.3], [0.3, -0.1], **opts), name)


def test_log_map_iterations_are_bounded() -> None:
    _raises_naming(lambda: solvers.log_map("randers", [-0.2, 0.3], [0.3, -0.1], max_iter=10**9),
                   "max_iter")


@pytest.mark.parametrize("metric, k, seed, name", [
    (None, 3, 0, "metric"), ("matsumoto", -1, 0, "k"), ("matsumoto", 10**12, 0, "pairs"),
    ("matsumoto", 3, -1, "seed"), ("matsumoto", 3, "abc", "seed"), ("matsumoto", 3, 1.5, "seed"),
])
def test_sample_pairs_checks_its_arguments(metric: Any, k: Any, seed: Any, name: str) -> None:
    _raises_naming(lambda: finsler.sample_pairs(metric, k, seed), name)


def test_sample_pairs_takes_a_name() -> None:
    assert finsler.sample_pairs("matsumoto", 3, 0).shape == (3, 2, 2)


@pytest.mark.parametrize("name, params, what", [
    ("sphere", {"radius": "abc"}, "radius"), ("sphere", {"radius": True}, "radius"),
    ("sphere", {"radius": 1 + 1j}, "radius"), ("matsumoto", {"height": None}, "height"),
    ("poincare", {"name": 1}, "name"), ("euclidean", {"n": 2.5}, "n"),
])
def test_metric_parameters_are_checked_against_their_types(name: str, params: dict,
                                                          what: str) -> None:
    _raises_naming(lambda: finsler.get_metric(name, **params), what)


def test_long_names_are_shortened() -> None:
    text = _raises_naming(lambda: finsler.get_metric("x" * 5000), "unknown metric")
    assert len(text) < 300
    text = _raises_naming(lambda: solvers.solve_geodesic("y" * 5000, [0, 0], [1, 1]), "metric")
    assert len(text) < 300


def test_load_policy_refuses_what_is_not_a_run() -> None:
    import learn

    text = _raises_naming(lambda: learn.load_policy("z" * 5000), "run")
    assert len(text) < 300
    _raises_naming(lambda: learn.load_policy(b"matsumoto"), "run", "bytes")
    _raises_naming(lambda: learn.load_policy("matsumoto", checkpoint=3), "checkpoint")


def test_load_policy_on_garbage_files_is_one_short_line(tmp_path: Any) -> None:
    import learn
    from learn.storage import CorruptFileError

    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text("[" * 100000)
    with pytest.raises(CorruptFileError) as err:
        learn.load_policy(run)
    assert "\n" not in str(err.value) and len(str(err.value)) < 400


@pytest.mark.parametrize("bad", ["0.1,0.2", {"a": 1}, None, np.array([0.1, 0.1]) + 1j])
def test_policy_methods_refuse_non_numeric_points(bad: Any) -> None:
    import learn

    policy = learn.load_policy("matsumoto")
    good = [0.1, 0.1]
    _raises_naming(lambda: policy.generate(bad, good), "starts")
    _raises_naming(lambda: policy.midpoint(good, bad), "goals")
    if bad is not None:  # None asks for the default pairs
        _raises_naming(lambda: policy.evaluate(bad), "pairs")


@pytest.mark.parametrize("depth", [-1, 2.5, "x", 10**6])
def test_policy_depth_is_bounded(depth: Any) -> None:
    import learn

    policy = learn.load_policy("matsumoto")
    _raises_naming(lambda: policy.generate([0.1, 0.1], [0.2, 0.1], depth=depth), "depth")


@pytest.mark.parametrize("eps", [-1, "x", float("nan"), 1j])
def test_policy_eps_is_checked(eps: Any) -> None:
    import learn

    policy = learn.load_policy("matsumoto")
    _raises_naming(lambda: policy.evaluate(np.array([[[0.1, 0.1], [0.2, 0.1]]]), eps=eps), "eps")


# -- overflow --------------------------------------------------------------------------
def test_huge_finite_vectors_have_finite_lengths() -> None:
    e = finsler.get_metric("euclidean")
    assert e.F([0, 0], [1e308, 1e308]) == pytest.approx(np.sqrt(2) * 1e308, rel=1e-12)
    m = finsler.get_metric("matsumoto")
    big = float(m.F([0.1, 0.15], [1e300, 0]))
    assert np.isfinite(big) and big == pytest.approx(1e300 * float(m.F([0.1, 0.15], [1, 0])),
                                                     rel=1e-12)


# -- user metrics ----------------------------------------------------------------------
def _user(F: Any, name: str, domain: Any = None) -> Metric:
    @dataclasses.dataclass(frozen=True)
    class User(Metric):
        task: ClassVar[Task] = Task(3, 0.1)

        @property
        def domain(self) -> Any:
            return Box((-1.0, -1.0), (1.0, 1.0)) if domain is None else domain

        def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
            return F(x, v)

    User.name = name  # type: ignore[misc]
    return User()


@pytest.mark.parametrize("F, what", [
    (lambda x, v: -ca.sqrt(ca.dot(v, v)), "finite and > 0"),
    (lambda x, v: ca.sqrt(-1 - ca.dot(v, v)), "finite and > 0"),
    (lambda x, v: 0 * v[0], "finite and > 0"),
    (lambda x, v: v, "scalar"),
    (lambda x, v: None, "scalar"),
    (lambda x, v: float(v[0]), "user-broken"),
], ids=["negative", "nan", "zero", "vector", "none", "float-of-symbol"])
def test_a_broken_user_metric_is_refused_by_name(F: Any, what: str) -> None:
    m = _user(F, "user-broken")
    for call in (lambda: m.cost([0.1, 0.1], [0.4, -0.2]),
                 lambda: solvers.solve_geodesic(m, [0.1, 0.1], [0.4, -0.2], segments=4),
                 lambda: solvers.exp_map(m, [0.1, 0.1], [0.3, -0.2])):
        _raises_naming(call, "user-broken", what)


def test_a_domain_that_is_not_a_domain_is_named() -> None:
    m = _user(lambda x, v: ca.sqrt(ca.dot(v, v)), "user-nodomain", domain="disk")
    _raises_naming(lambda: m.cost([0.1, 0.1], [0.4, -0.2]), "user-nodomain", "domain")


def test_a_good_user_metric_solves() -> None:
    m = _user(lambda x, v: ca.sqrt(ca.dot(v, v)), "user-good")
    res = solvers.solve_geodesic(m, [0.1, 0.1], [0.4, -0.2], segments=4)
    assert res.converged and res.length == pytest.approx(np.hypot(0.3, 0.3), rel=1e-9)


# -- output paths ----------------------------------------------------------------------
def test_a_dangling_symlink_is_refused_like_a_missing_folder(tmp_path: Any) -> None:
    from finsler.infra.files import OutputError, check_output_path

    link = tmp_path / "dangling.npy"
    os.symlink(tmp_path / "nowhere" / "x.npy", link)
    with pytest.raises(OutputError, match="symbolic link"):
        check_output_path(link)
    assert not (tmp_path / "nowhere").exists()


def test_certify_out_through_a_dangling_symlink_is_refused(tmp_path: Any) -> None:
    import subprocess
    import sys
    from pathlib import Path

    os.symlink("nowhere/x.npy", tmp_path / "dangling.npy")
    exe = Path(sys.executable).with_name("geodesics")
    proc = subprocess.run([str(exe), "certify", "--metric", "poincare", "--start", "0.1,0.2",
                           "--goal", "0.4,-0.3", "--mesh", "coarse", "--out", "dangling.npy"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert "symbolic link" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "nowhere").exists()


@pytest.mark.parametrize("make, what", [
    (lambda: finsler.Sphere(radius="abc"), "radius"),
    (lambda: finsler.Sphere(radius=True), "radius"),
    (lambda: finsler.Sphere(radius=1 + 1j), "radius"),
    (lambda: finsler.Matsumoto(height=None), "height"),
    (lambda: finsler.Euclidean(n=2.5), "n"),
])
def test_metric_classes_check_their_parameter_types(make: Any, what: str) -> None:
    _raises_naming(make, what)
