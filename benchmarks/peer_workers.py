"""The peers' side of ``benchmarks/peers.py``: run by a peer's own interpreter (the geomstats
or finslerax venv, see peers.py's docstring) as ``python peer_workers.py geomstats|finslerax``
with a JSON job on stdin; prints the JSON result on stdout. Only the standard library and
numpy are imported at module level (the peer's packages inside the workers); nothing of the
project is imported here.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numpy as np


def timed(fn: Any) -> tuple[Any, float, str | None]:
    """``(result or None, wall seconds, error text or None)`` of ``fn()``."""
    t0 = time.perf_counter()
    try:
        out = fn()
        return out, time.perf_counter() - t0, None
    except Exception as err:  # a peer's failure is a result of the benchmark
        return None, time.perf_counter() - t0, f"{type(err).__name__}: {err}"[:300]


def _geomstats_worker(job: dict) -> dict:
    import geomstats
    import geomstats.backend as gs
    from geomstats.geometry.euclidean import Euclidean
    from geomstats.geometry.riemannian_metric import RiemannianMetric
    from geomstats.numerics.bvp import ScipySolveBVP
    from geomstats.numerics.geodesic import (
        ExpODESolver,
        LogODESolver,
        LogShootingSolver,
        PathStraightening,
    )

    name, p = job["metric"], job["params"]

    def factor(x: Any) -> Any:  # the conformal factor f(x), F = f |v|
        if name == "poincare":
            return 2.0 / (1.0 - gs.sum(x * x, axis=-1))
        c = gs.array([p["cx"], p["cy"]])
        r2 = gs.sum((x - c) ** 2, axis=-1)
        return 1.0 + p["amplitude"] * gs.exp(-r2 / (2.0 * p["sigma"] ** 2))

    class MatrixMetric(RiemannianMetric):
        def metric_matrix(self, base_point: Any = None) -> Any:
            f = factor(base_point)
            return gs.einsum("...,ij->...ij", f * f, gs.eye(2))

    space = Euclidean(2, equip=False)
    space.equip_with_metric(MatrixMetric)
    space.metric.exp_solver = ExpODESolver(space)
    check = [float(gs.sqrt(gs.einsum("i,ij,j->", v, space.metric.metric_matrix(x), v)))
             for x, v in np.asarray(job["check"])]
    pairs = np.asarray(job["pairs"], dtype=np.float64)
    if job.get("task") == "exp":
        from geomstats.numerics.ivp import ScipySolveIVP

        vel = np.asarray(job["velocities"], dtype=np.float64)
        rows = []
        for setting, solver in (
                ("defaults (10 Euler steps)", ExpODESolver(space)),
                ("accurate (DOP853, rtol=atol=1e-12)", ExpODESolver(
                    space, integrator=ScipySolveIVP(method="DOP853", rtol=1e-12,
                                                    atol=1e-12)))):
            space.metric.exp_solver = solver

            def shoot(x: np.ndarray, v: np.ndarray) -> dict:
                return {"point": np.asarray(space.metric.exp(gs.array(v), gs.array(x)),
                                            float).tolist()}

            _, setup, _ = timed(lambda: shoot(pairs[0, 0], vel[0]))
            per = []
            for (x, _y), v in zip(pairs, vel):
                out, sec, err = timed(lambda x=x, v=v: shoot(x, v))
                per.append({"seconds": sec, "error": err, **(out or {})})
            rows.append({"method": "ExpODESolver", "setting": setting, "kind": "exp",
                         "setup": setup, "per_pair": per})
        return {"peer": "geomstats", "version": geomstats.__version__, "check": check,
                "rows": rows}
    settings = [
        ("LogODESolver", "defaults (10 nodes, tol 1e-3)", "log",
         lambda: LogODESolver(space, use_jac=False)),
        ("LogODESolver", "accurate (50 nodes, tol 1e-8)", "log",
         lambda: LogODESolver(space, n_nodes=50, integrator=ScipySolveBVP(tol=1e-8),
                              use_jac=False)),
        ("LogShootingSolver", "defaults", "log", lambda: LogShootingSolver(space)),
        ("PathStraightening", "defaults (100 nodes)", "path",
         lambda: PathStraightening(space)),
        ("PathStraightening", "accurate (257 nodes)", "path",
         lambda: PathStraightening(space, n_nodes=257)),
    ]
    rows = []
    for method, setting, kind, make in settings:
        solver = make()
        space.metric.log_solver = solver

        def one(x: np.ndarray, y: np.ndarray, solver: Any = solver, kind: str = kind) -> dict:
            if kind == "log":
                v = space.metric.log(gs.array(y), gs.array(x))
                return {"velocity": np.asarray(v, float).tolist(),
                        "length": float(space.metric.norm(v, gs.array(x)))}
            path = solver.discrete_geodesic_bvp(gs.array(y), gs.array(x))
            return {"path": np.asarray(path, float).tolist()}

        _, setup, _ = timed(lambda: one(pairs[0, 0], pairs[0, 1]))
        per = []
        for x, y in pairs:
            out, sec, err = timed(lambda x=x, y=y: one(x, y))
            per.append({"seconds": sec, "error": err, **(out or {})})
        rows.append({"method": method, "setting": setting, "kind": kind, "setup": setup,
                     "per_pair": per})
    return {"peer": "geomstats", "version": geomstats.__version__, "check": check,
            "rows": rows}


def _finslerax_worker(job: dict) -> dict:
    import equinox as eqx
    import finslerax as fx
    import jax
    import jax.numpy as jnp
    from finslerax.solvers import AVBDSolver, GaussNewtonGeodesic

    name, p, n = job["metric"], job["params"], int(job["segments"])
    space = fx.EuclideanSpace(2)
    if job.get("task") == "exp":
        return _finslerax_exp(job, fx, jax, jnp, eqx, space)
    if name == "randers":
        wind = jnp.array(p["wind"])
        metric = fx.Randers(space, h_net=lambda x: jnp.eye(2), w_net=lambda x: wind,
                            wind_mode="raw")
    else:
        height = float(p["height"])

        class Matsumoto(fx.FinslerMetric):
            def metric_fn(self, x: Any, v: Any) -> Any:
                beta = jnp.dot(-2.0 * height * x, v)
                alpha = jnp.sqrt(jnp.dot(v, v) + beta * beta)
                return alpha * alpha / (alpha - beta)

        metric = Matsumoto(space)
    check = [float(metric.metric_fn(jnp.array(x), jnp.array(v)))
             for x, v in np.asarray(job["check"])]
    pairs = jnp.asarray(np.asarray(job["pairs"], dtype=np.float64))
    x0, y0, xs, ys = pairs[0, 0], pairs[0, 1], pairs[:, 0], pairs[:, 1]
    rows = []
    if job.get("task") == "throughput":
        return _finslerax_throughput(job, metric, jax, eqx, GaussNewtonGeodesic, pairs, n,
                                     check, fx.__version__)
    for method, label, solver in (
            ("GaussNewtonGeodesic", "defaults", GaussNewtonGeodesic()),
            ("AVBDSolver", "defaults", AVBDSolver()),
            ("AVBDSolver", "2000 iterations", AVBDSolver(iterations=2000))):
        single = eqx.filter_jit(
            lambda m, a, b, s=solver: s.solve(m, a, b, n_steps=n, train_mode=False).xs)
        batched = eqx.filter_jit(lambda m, a, b, s=solver: jax.vmap(
            lambda u, w: s.solve(m, u, w, n_steps=n, train_mode=False).xs)(a, b))
        _, setup, err0 = timed(lambda f=single: f(metric, x0, y0).block_until_ready())
        per = []
        for x, y in pairs:
            out, sec, err = timed(lambda x=x, y=y, f=single: np.asarray(
                f(metric, x, y).block_until_ready()))
            per.append({"seconds": sec, "error": err,
                        "path": None if out is None else out.tolist()})
        rows.append({"method": method, "setting": f"{label}, {n} segments, single",
                     "kind": "path", "setup": setup, "per_pair": per,
                     "setup_error": err0})
        _, bsetup, _ = timed(lambda f=batched: f(metric, xs, ys).block_until_ready())
        out, sec, err = timed(lambda f=batched: np.asarray(
            f(metric, xs, ys).block_until_ready()))
        per = [{"seconds": sec / len(pairs), "error": err,
                "path": None if out is None else out[k].tolist()} for k in range(len(pairs))]
        rows.append({"method": method, "setting": f"{label}, {n} segments, batched (vmap)",
                     "kind": "path", "setup": bsetup, "per_pair": per})
    return {"peer": "finslerax", "version": fx.__version__, "check": check, "rows": rows}


def _finslerax_throughput(job: dict, metric: Any, jax: Any, eqx: Any, gn_cls: Any,
                          pairs: Any, n: int, check: list, version: str) -> dict:
    """Gauss-Newton batched with ``jax.vmap`` over all pairs: compiled on the batch's shape
    first (reported as ``setup``), then timed (wall and CPU)."""
    solver = gn_cls()
    batched = eqx.filter_jit(lambda m, a, b: jax.vmap(
        lambda u, w: solver.solve(m, u, w, n_steps=n, train_mode=False).xs)(a, b))
    xs, ys = pairs[:, 0], pairs[:, 1]
    _, setup, _ = timed(lambda: batched(metric, xs, ys).block_until_ready())
    secs, cpus = [], []
    for _ in range(int(job.get("repeats", 1))):
        c0 = time.process_time()
        out, sec, err = timed(lambda: np.asarray(batched(metric, xs, ys)
                                                  .block_until_ready()))
        secs.append(sec)
        cpus.append(time.process_time() - c0)
    return {"peer": "finslerax", "version": version, "check": check, "setup": setup,
            "seconds": float(np.median(secs)), "cpu": float(np.median(cpus)), "error": err,
            "paths": None if out is None else out.tolist()}


def _finslerax_exp(job: dict, fx: Any, jax: Any, jnp: Any, eqx: Any, space: Any) -> dict:
    """finslerax's ExponentialMap (RK4, fixed steps) on the Poincare disk."""

    class Poincare(fx.FinslerMetric):
        def metric_fn(self, x: Any, v: Any) -> Any:
            return 2.0 * jnp.sqrt(jnp.dot(v, v)) / (1.0 - jnp.dot(x, x))

    metric = Poincare(space)
    check = [float(metric.metric_fn(jnp.array(x), jnp.array(v)))
             for x, v in np.asarray(job["check"])]
    xs = jnp.asarray(np.asarray(job["pairs"], dtype=np.float64)[:, 0])
    vs = jnp.asarray(np.asarray(job["velocities"], dtype=np.float64))
    rows = []
    for setting, em in (("defaults (100 RK4 steps)", fx.ExponentialMap()),
                        ("1000 RK4 steps", fx.ExponentialMap(max_steps=1000))):
        single = eqx.filter_jit(lambda m, a, b, e=em: e.shoot(m, a, b))
        batched = eqx.filter_jit(lambda m, a, b, e=em: jax.vmap(
            lambda u, w: e.shoot(m, u, w))(a, b))
        _, setup, _ = timed(lambda f=single: f(metric, xs[0], vs[0]).block_until_ready())
        per = []
        for x, v in zip(xs, vs):
            out, sec, err = timed(lambda x=x, v=v, f=single: np.asarray(
                f(metric, x, v).block_until_ready()))
            per.append({"seconds": sec, "error": err,
                        "point": None if out is None else out.tolist()})
        rows.append({"method": "ExponentialMap", "setting": f"{setting}, single",
                     "kind": "exp", "setup": setup, "per_pair": per})
        _, bsetup, _ = timed(lambda f=batched: f(metric, xs, vs).block_until_ready())
        out, sec, err = timed(lambda f=batched: np.asarray(f(metric, xs, vs)
                                                           .block_until_ready()))
        rows.append({"method": "ExponentialMap", "setting": f"{setting}, batched (vmap)",
                     "kind": "exp", "setup": bsetup, "per_pair": [
                         {"seconds": sec / len(xs), "error": err,
                          "point": None if out is None else out[k].tolist()}
                         for k in range(len(xs))]})
    return {"peer": "finslerax", "version": fx.__version__, "check": check, "rows": rows}


def worker_main(peer: str) -> None:
    job = json.load(sys.stdin)
    out = _geomstats_worker(job) if peer == "geomstats" else _finslerax_worker(job)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    if len(sys.argv) != 2 or sys.argv[1] not in ("geomstats", "finslerax"):
        raise SystemExit("usage: python peer_workers.py geomstats|finslerax < job.json")
    worker_main(sys.argv[1])
