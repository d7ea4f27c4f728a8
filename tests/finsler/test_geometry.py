"""Derived geometry once, on the metric (issue 23 part 4): the spray of finsler.geometry, the
metric's Hessians, and the one caching scheme (cached properties and Metric.derived; no
module-level cache keyed by a metric)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import finsler
import solvers.continuum.expmap
from finsler import InputError, geometry
from solvers import ExpStatus, exp_map
from solvers.continuum.spectral import spectral_nlp
from solvers.seeding.graph import graph_seeder
from solvers.transcription import energy_nlp, minmax_nlp

ROOT = Path(__file__).resolve().parents[2]


def _points(m: finsler.Metric, k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return m.domain.sample(k, rng), rng.normal(size=(k, m.dim))


# -- the spray -----------------------------------------------------------------------------
def test_poincare_spray_is_the_conformal_geodesic_equation() -> None:
    # F = e^phi |v| with phi = log 2 - log(1 - |x|^2): x'' = |v|^2 grad phi - 2 (grad phi . v) v
    m = finsler.get_metric("poincare")
    sp = geometry.spray(m)
    for x, v in zip(*_points(m, 6, seed=3), strict=True):
        grad_phi = 2.0 * x / (1.0 - x @ x)
        exact = (v @ v) * grad_phi - 2.0 * (grad_phi @ v) * v
        acc, g = sp.acceleration(x, v)
        np.testing.assert_allclose(acc, exact, rtol=1e-13, atol=1e-13)
        # g is the metric's fundamental tensor, the same graph: equal to the last bit
        assert np.array_equal(g, np.asarray(m.casadi_hessian(x, v)))
        np.testing.assert_allclose(g, (4.0 / (1.0 - x @ x) ** 2) * np.eye(2), rtol=1e-14,
                                   atol=1e-14)


def test_spray_of_a_constant_wind_is_zero() -> None:
    m = finsler.get_metric("randers")
    sp = geometry.spray(m)
    for x, v in zip(*_points(m, 4, seed=4), strict=True):
        acc, _ = sp.acceleration(x, v)
        np.testing.assert_allclose(acc, 0.0, atol=1e-15)


def test_matsumoto_spray_solves_the_euler_lagrange_equation() -> None:
    # d/dt dE/dv (x + t v, v + t a) = dE/dx (x, v) with E = F**2 / 2 from numeric F only
    # (central differences, 4th order): independent of the symbolic derivation
    m = finsler.get_metric("matsumoto")
    sp = geometry.spray(m)

    def energy(x: np.ndarray, v: np.ndarray) -> np.ndarray:
        return 0.5 * m.F(x, v, check=False) ** 2

    def grad(f, z: np.ndarray, k: float) -> np.ndarray:  # f: (N, d) -> (N,), at rows of z
        e = np.eye(z.shape[-1])[:, None, :] * k
        return np.stack([(-f(z + 2 * ei) + 8 * f(z + ei) - 8 * f(z - ei) + f(z - 2 * ei))
                         / (12 * k) for ei in e], -1)

    x = np.array([[0.05, -0.05], [-0.1, 0.12], [0.0, 0.2]])
    v = np.array([[0.1, 0.05], [0.3, -0.2], [-0.1, 0.4]])
    acc = np.stack([sp.acceleration(a, b)[0] for a, b in zip(x, v, strict=True)])
    h = 1e-3
    ts = np.array([-2, -1, 1, 2])[:, None, None] * h

    def ev(t: np.ndarray) -> np.ndarray:  # dE/dv along the curve (x + t v, v + t a)
        return grad(lambda w: energy(x + t * v, w), v + t * acc, 1e-4)

    lhs = (-ev(ts[3]) + 8 * ev(ts[2]) - 8 * ev(ts[1]) + ev(ts[0])) / (12 * h)
    rhs = grad(lambda y: energy(y, v), x, 1e-4)
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-8)


# numbers of the spray and exp_map before the spray moved to finsler.geometry (commit
# 7e15455, solvers/continuum/expmap.py's own Hessian): the move must not change them
OLD = {
    "matsumoto": ([0.05, -0.05], [0.1, 0.05], [0.015455107892671235, 0.017548317442747968],
                  [0.15687663647556907, 0.008634639011685654]),
    "poincare": ([0.3, -0.2], [0.5, 0.4], [0.12183908045977021, -0.3172413793103448],
                 [0.7446454820483936, 0.029165164842530813]),
    "sphere": ([0.4, 0.3], [-0.2, 0.3], [-0.0896, -0.052800000000000014],
               [0.15162008068557303, 0.5740691937349396]),
}


@pytest.mark.parametrize("name", sorted(OLD))
def test_spray_and_exp_map_give_the_old_numbers(name: str) -> None:
    x, v, acc, point = (np.array(a) for a in OLD[name])
    m = finsler.get_metric(name)
    np.testing.assert_allclose(geometry.spray(m).acceleration(x, v)[0], acc, rtol=1e-14,
                               atol=1e-16)
    r = exp_map(m, x, v)
    assert r.status is ExpStatus.SUCCESS
    np.testing.assert_allclose(r.point, point, rtol=0, atol=1e-12)


def test_exp_map_of_randers_is_the_straight_line() -> None:
    m = finsler.get_metric("randers")
    x, v = np.array([0.2, 0.1]), np.array([-0.4, 0.3])
    r = exp_map(m, x, v)
    np.testing.assert_allclose(r.point, x + v, rtol=0, atol=1e-13)


def test_spray_is_refused_for_a_non_smooth_metric() -> None:
    with pytest.raises(InputError, match="not smooth"):
        geometry.spray(finsler.get_metric("carlike"))


# -- built once per metric -----------------------------------------------------------------
def test_derived_geometry_is_built_once_per_metric() -> None:
    m = finsler.get_metric("matsumoto")
    expmap = solvers.continuum.expmap
    assert expmap.spray is geometry.spray and expmap.Spray is geometry.Spray
    sp = geometry.spray(m)
    assert isinstance(sp, geometry.Spray) and geometry.spray(m) is sp
    assert m.casadi_hessian is m.casadi_hessian and m.casadi_hessian_x is m.casadi_hessian_x
    assert energy_nlp(m, 4) is energy_nlp(m, 4) and energy_nlp(m, 4, warm=True) is not \
        energy_nlp(m, 4)
    assert minmax_nlp(m, 4) is minmax_nlp(m, 4)
    assert spectral_nlp(m, 6) is spectral_nlp(m, 6)
    assert graph_seeder(m) is graph_seeder(m)
    assert geometry.spray(finsler.get_metric("matsumoto")) is sp  # the registry shares m
    other = type(m)()  # an equal metric, another instance: its own cache, dropped with it
    assert geometry.spray(other) is not sp and geometry.spray(other) is geometry.spray(other)


def test_panda_kinematics_lowered_once_per_process() -> None:
    from finsler.metrics import panda

    fk = panda.lowered_frame_positions()
    assert panda.lowered_frame_positions() is fk
    m = finsler.get_metric("panda-pole")
    q = np.zeros((1, 7))
    (flat,) = fk(q)
    assert np.array_equal(m.frame_positions(q)[0], flat.reshape(3, 10).T)


def test_hessian_in_x_is_the_length_integrands_second_derivative() -> None:
    # Poincare: F = 2 |v| / (1 - |x|^2); Hess_x F = 2|v| (2 I / s^2 + 8 x x' / s^3), s = 1 - |x|^2
    m = finsler.get_metric("poincare")
    for x, v in zip(*_points(m, 4, seed=5), strict=True):
        s = 1.0 - x @ x
        exact = 2 * np.linalg.norm(v) * (2 * np.eye(2) / s**2 + 8 * np.outer(x, x) / s**3)
        np.testing.assert_allclose(np.asarray(m.casadi_hessian_x(x, v)), exact, rtol=1e-13)


# -- one caching scheme ----------------------------------------------------------------------

def _is_cache_decorator(node: ast.expr) -> bool:
    target = node.func if isinstance(node, ast.Call) else node
    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
    return name in ("lru_cache", "cache")


def _takes_metric(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    args = fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs
    def is_metric(a: ast.arg) -> bool:
        note = "" if a.annotation is None else ast.unparse(a.annotation).replace("MetricSpec", "")
        return "metric" in a.arg.lower() or "Metric" in note or (a.arg == "m" and not note)

    return any(is_metric(a) for a in args)


def metric_keyed_caches(source: str, label: str) -> list[str]:
    """``label:function`` of every function cached by ``functools.lru_cache``/``cache`` that
    takes a metric, and ``label:name`` of every module-level dict annotated with ``Metric``
    keys."""
    tree = ast.parse(source)
    found = [f"{label}:{node.name}" for node in ast.walk(tree)
             if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
             and any(_is_cache_decorator(d) for d in node.decorator_list) and _takes_metric(node)]
    for node in tree.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.annotation, ast.Subscript):
            key = node.annotation.slice
            first = key.elts[0] if isinstance(key, ast.Tuple) else key
            if ast.unparse(first) in ("Metric", "finsler.Metric"):
                found.append(f"{label}:{ast.unparse(node.target)}")
    return found


_DICT_MAKERS = ("dict", "defaultdict", "OrderedDict", "WeakValueDictionary")


def _module_dicts(tree: ast.Module) -> set[str]:
    """Names bound at module level to a dict (a display or a dict-making call)."""
    names = set()
    for node in tree.body:
        value = node.value if isinstance(node, (ast.Assign, ast.AnnAssign)) else None
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AnnAssign) else [])
        is_dict = isinstance(value, (ast.Dict, ast.DictComp)) or (
            isinstance(value, ast.Call) and ast.unparse(value.func).split(".")[-1] in _DICT_MAKERS)
        if is_dict:
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return names


def _holds_metric_or_id(key: ast.expr, local: dict[str, ast.expr]) -> bool:
    """Whether a key expression holds a metric (a name or attribute called ``m``,
    ``metric`` or ``*metric*``) or an ``id(...)``, looking through local tuple names."""
    if isinstance(key, ast.Name) and key.id in local:
        key = local[key.id]
    if any(isinstance(n, ast.Call) and ast.unparse(n.func) == "id" for n in ast.walk(key)):
        return True
    for node in key.elts if isinstance(key, ast.Tuple) else [key]:  # the key's own parts:
        name = (node.id if isinstance(node, ast.Name)  # values computed from a metric
                else node.attr if isinstance(node, ast.Attribute) else None)  # (its name,
        if name is not None and (name == "m" or "metric" in name.lower()):  # parameters)
            return True  # are not the metric
    return False


def keyed_by_metric_or_id(source: str, label: str) -> list[str]:
    """``label:NAME`` of every module-level dict looked up or stored with a key that holds
    a metric or an ``id()``, and ``label:line`` of every other container keyed by ``id()``
    (a dict display or comprehension, a subscript, ``in``, ``.add``/``.get``)."""
    tree = ast.parse(source)
    dicts, found = _module_dicts(tree), set()
    scopes = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    for scope in [tree, *scopes]:
        local = {t.id: n.value for n in ast.walk(scope) if isinstance(n, ast.Assign)
                 for t in n.targets if isinstance(t, ast.Name)}
        for node in ast.walk(scope):
            keys: list[tuple[str | None, ast.expr]] = []
            if isinstance(node, ast.Subscript):
                keys.append((getattr(node.value, "id", None), node.slice))
            elif isinstance(node, ast.Compare) and any(
                    isinstance(op, (ast.In, ast.NotIn)) for op in node.ops):
                keys += [(getattr(c, "id", None), node.left) for c in node.comparators]
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr in ("get", "setdefault", "pop", "add") and node.args):
                keys.append((getattr(node.func.value, "id", None), node.args[0]))
            elif isinstance(node, ast.DictComp):
                keys.append((None, node.key))
            elif isinstance(node, ast.Dict):
                keys += [(None, k) for k in node.keys if k is not None]
            for owner, key in keys:
                if owner in dicts and _holds_metric_or_id(key, local):
                    found.add(f"{label}:{owner}")
                elif any(isinstance(n, ast.Call) and ast.unparse(n.func) == "id"
                         for n in ast.walk(key)):
                    found.add(f"{label}:{getattr(key, 'lineno', '?')}")
    return sorted(found)


def test_the_wider_scan_finds_keys_holding_a_metric_or_an_id() -> None:
    src = ("_SUITES: dict[Any, Suite] = {}\n"
           "_RUNS = {}\n"
           "_NAMES: dict[str, int] = {}\n"
           "def f(self, m, oracle, seed):\n"
           "    key = (type(self).__qualname__, m, oracle, seed)\n"
           "    if key not in _SUITES:\n"
           "        _SUITES[key] = 1\n"
           "    _NAMES[m.name] = 2\n"  # keyed by the metric's name: not the metric
           "    return _RUNS.get((id(oracle), seed))\n"
           "def g(items):\n"
           "    seen = set()\n"
           "    seen.add(id(items))\n"
           "    return {id(x): x for x in items}\n"
           "def h(metric):\n"
           "    return metric.derived('x', dict)[('a', 1)]\n")
    assert keyed_by_metric_or_id(src, "x") == ["x:12", "x:13", "x:_RUNS", "x:_SUITES"]


def test_no_container_is_keyed_by_a_metric_or_an_id() -> None:
    """Caches keyed by a metric live on the metric (``Metric.derived``), never in a module
    dict whose key holds a metric (issue 49: the widened guard); nothing is keyed by
    ``id()`` (an id is reused once its object dies)."""
    files = [p for pkg in ("finsler", "solvers", "learn", "validation")
             for p in sorted((ROOT / pkg).rglob("*.py"))]
    found = {hit for p in files
             for hit in keyed_by_metric_or_id(p.read_text(), str(p.relative_to(ROOT)))}
    assert found == set()


def test_the_scan_finds_a_cache_keyed_by_a_metric() -> None:
    src = ("import functools\n"
           "@functools.lru_cache(maxsize=8)\ndef a(metric, n): ...\n"
           "@functools.cache\ndef b(m: Metric): ...\n"
           "@lru_cache\ndef c(thing: 'finsler.Metric'): ...\n"
           "@functools.lru_cache(maxsize=16)\ndef gauss(order: int): ...\n"
           "@functools.lru_cache(maxsize=1)\ndef model(): ...\n"
           "def plain(metric): ...\n"
           "_BY_METRIC: dict[Metric, int] = {}\n"
           "_BY_SPEC: dict[MetricSpec, Metric] = {}\n")
    assert metric_keyed_caches(src, "x") == ["x:a", "x:b", "x:c", "x:_BY_METRIC"]


def test_no_module_cache_is_keyed_by_a_metric() -> None:
    files = [p for pkg in ("finsler", "solvers", "learn", "validation")
             for p in sorted((ROOT / pkg).rglob("*.py"))]
    assert len(files) > 20
    found = {hit for p in files
             for hit in metric_keyed_caches(p.read_text(), str(p.relative_to(ROOT)))}
    assert found == set()
