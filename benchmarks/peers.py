"""Side-by-side benchmark of the exact solvers against geomstats 2.8 and finslerax 1.1
(issue 14 part 5): the same pairs, one table of time per pair, error and failures.

Metrics and references
----------------------
* ``poincare`` (Riemannian, exact distance known) and ``bump``, a conformal metric without a
  closed form, ``F(x, v) = (1 + A exp(-|x - c|^2 / (2 s^2))) |v|`` on the disk of radius 0.8
  (defined below as a project metric, one SX expression). geomstats gets each only as its
  metric matrix ``G(x) = f(x)^2 I`` on ``Euclidean(2)``, with its generic solvers: ``LogODESolver``
  (defaults: 10 nodes, ``ScipySolveBVP`` tol 1e-3; accurate: 50 nodes, tol 1e-8; both
  ``use_jac=False``: there is no ``jacobian_christoffels`` for a bare metric matrix),
  ``LogShootingSolver`` (defaults, with the default ``ExpODESolver``) and
  ``PathStraightening`` (defaults: 100 nodes; accurate: 257 nodes).
* ``randers`` (constant wind, exact distance known) and ``matsumoto`` (no closed form, not
  convex everywhere). finslerax gets each as ``F(x, v)``: its ``Randers`` with
  ``wind_mode="raw"`` (equal to the project's F; the default "soft" wind differs by ~1e-7)
  and a ``FinslerMetric`` subclass for Matsumoto, solved with ``GaussNewtonGeodesic`` and
  ``AVBDSolver`` (defaults, and 2000 iterations; ``train_mode=False`` for early stopping),
  one pair per call ("single") and batched over all pairs with ``jax.vmap``, every call
  ``equinox.filter_jit``-compiled (compile time reported apart).
* The project: ``solve_geodesic`` at the task size (energy stage, no min-max) and at 256
  segments, ``distance`` (default rtol 1e-8), ``solve_geodesic(tol=1e-7)`` when that
  parameter exists (issue 14 part 3; otherwise the row says it was skipped), and
  ``log_map`` (Riemannian rows and Randers).

* ``exp``: exp maps on the Poincare pairs, with the closed-form initial velocity of the
  geodesic from x to y (Moebius maps), so the error is ``|exp(x, v) - y|_max``: the
  project's ``exp_map`` (spray from the SX expression, DOP853 at 1e-13), geomstats'
  ``ExpODESolver`` (defaults: 10 Euler steps; accurate: scipy DOP853 at 1e-12) and
  finslerax's ``ExponentialMap`` (RK4: defaults 100 steps, and 1000 steps; single, batched).

Every peer's own formula of the metric is checked against the project's ``F`` at sample
points (the largest relative difference is printed) so that all rows solve the same problem.

What the columns mean
---------------------
``length`` of a method: for path methods, the length of the returned polyline (each
segment's eq. 58 quadrature of the project's F, order 8), an upper bound of ``d`` whatever N;
for log methods (geomstats' ``LogODESolver``/``LogShootingSolver``, the project's
``log_map``) ``F(x, v)`` of the returned initial velocity, i.e. geomstats' ``dist``; for
``distance``/``tol`` the length they return. ``err`` is ``(length - d) / d`` where ``d`` is
exact, else ``(length - best) / best`` with ``best`` the shortest upper bound found on that
pair (path lengths and converged ``distance`` values): "length vs the shortest found".
A pair is a failure when the method raised, returned non-finite numbers, a path leaving
the domain (Matsumoto: the unit disk) or not converged (project status), or, for log
methods, a velocity whose geodesic (integrated by the project's ``exp_map`` at 1e-13)
misses the goal by more than 1e-4 (``max miss``: the largest miss of
the non-failed pairs). Median and max of ``|err|`` are over the non-failed
pairs. Times are wall seconds per pair on one thread after one warm-up pair (building
NLPs / JIT compilation excluded, reported as ``setup``); batched rows divide the batch's
time by the number of pairs.

Peer environments (each peer in its own venv, driven by subprocess with JSON on stdin and
stdout; no peer is a dependency of the project; geomstats 2.8 imports ``numpy.trapz`` and
needs ``numpy<2`` and ``autograd``)::

    python3.11 -m venv PEERS/geomstats
    PEERS/geomstats/bin/pip install "numpy<2" autograd geomstats==2.8.0 scipy
    python3.11 -m venv PEERS/finslerax
    PEERS/finslerax/bin/pip install "jax[cpu]" finslerax==1.1.0

(``PEERS`` any folder outside the project.) Usage (from the project's venv)::

    python benchmarks/peers.py [--pairs 10] [--seed 0]
        [--metrics poincare,bump,randers,matsumoto,exp]
        [--geomstats-python PEERS/geomstats/bin/python]
        [--finslerax-python PEERS/finslerax/bin/python] [--json OUT.json]
    python benchmarks/peers.py --throughput [--throughput-pairs 1000] [--quality-pairs 100]
        [--batch-sizes 1,10,100,1000] [--seed 1124] --finslerax-python ...

The interpreters default to the environment variables ``GEOMSTATS_PYTHON`` and
``FINSLERAX_PYTHON``.

Throughput (``--throughput``, issue 21): on ``--throughput-pairs`` fresh Matsumoto pairs
(64 segments) and Randers pairs (16 segments), the project's ``solve_batch`` (the batched
Newton path, ``workers=1``) against finslerax's Gauss-Newton batched with ``jax.vmap``
(compiled first; its compile time reported apart): wall and CPU time per pair, energy
against the lowest energy found on each pair (Matsumoto) or the error of the length
against the exact distance (Randers), failures. On the first ``--quality-pairs`` Matsumoto
pairs the reference is stricter: the lowest energy of every run, including the project's
IPOPT default of the landed code (``method="ipopt"``) and ``--reference-rounds`` wide
Newton multistarts (78 starts at the full size and 30 restarts each, seeds 0, 1, ...).
Last, the project's time per pair against the batch size. Every time is the median of
``--repeats`` runs.

A peer whose interpreter is missing or fails to import is skipped with the reason printed.
The peers' side is ``benchmarks/peer_workers.py`` (``python peer_workers.py
geomstats|finslerax``, JSON job on stdin, run by the peer's interpreter; only the standard
library and numpy at module level).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from peer_workers import timed

#: Interpreters of the peers' venvs: ``--geomstats-python`` / ``--finslerax-python``, else
#: these environment variables (a peer with neither is skipped, with the reason printed).
PEER_ENV = {"geomstats": "GEOMSTATS_PYTHON", "finslerax": "FINSLERAX_PYTHON"}

#: Parameters of the conformal "bump" metric (shared by the project's and geomstats' side).
BUMP = {"amplitude": 2.0, "cx": 0.15, "cy": 0.05, "sigma": 0.25, "radius": 0.8}
#: Randers wind (the registered metric's default) and Matsumoto height.
WIND = (0.5, 0.2)
HEIGHT = 1.0
#: Radius of the disk the pairs of the disk metrics are drawn from.
PAIR_RADIUS = {"poincare": 0.7, "bump": 0.7, "matsumoto": 0.9}
#: A log method's velocity whose geodesic misses the goal by more than this (max norm, in
#: coordinates of a domain of size ~1) gave a wrong answer: a failure. Smaller misses are
#: shown in the ``max miss`` column.
MISS_TOL = 1e-4
#: Sections of the table and the peers run in each ("exp": exp maps on the Poincare disk).
SECTIONS = {"poincare": ("geomstats",), "bump": ("geomstats",), "randers": ("finslerax",),
            "matsumoto": ("finslerax",), "exp": ("geomstats", "finslerax")}
#: The peers' worker script, run by their interpreters (JSON job on stdin, result on stdout).
WORKER_FILE = Path(__file__).resolve().with_name("peer_workers.py")
ONE_THREAD = {
    "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
    "JAX_ENABLE_X64": "1", "JAX_PLATFORMS": "cpu", "GEOMSTATS_BACKEND": "autograd",
}


# ----------------------------------------------------------------------------------------
# Driver (the project's environment)
# ----------------------------------------------------------------------------------------
def bump_metric() -> Any:
    """The conformal test metric without a closed form, as a project metric."""
    from dataclasses import dataclass
    from typing import ClassVar

    import casadi as ca

    from finsler.domains import Disk
    from finsler.metrics.base import Metric, Task

    @dataclass(frozen=True)
    class Bump(Metric):
        """``F(x, v) = (1 + A exp(-|x - c|^2 / (2 s^2))) |v|`` on a disk: a costly hill."""

        amplitude: float = BUMP["amplitude"]
        cx: float = BUMP["cx"]
        cy: float = BUMP["cy"]
        sigma: float = BUMP["sigma"]
        radius: float = BUMP["radius"]

        name: ClassVar[str] = "bump"
        task: ClassVar[Task] = Task(depth=5, eps=0.3)
        reversible: ClassVar[bool] = True

        @property
        def domain(self) -> Disk:
            return Disk(radius=self.radius)

        def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
            r2 = (x[0] - self.cx) ** 2 + (x[1] - self.cy) ** 2
            return (1.0 + self.amplitude * ca.exp(-r2 / (2.0 * self.sigma**2))) * ca.sqrt(
                ca.dot(v, v))

    return Bump()


def make_pairs(name: str, m: Any, k: int, seed: int) -> np.ndarray:
    """``k`` pairs ``(k, 2, 2)`` at least 0.2 apart, drawn with ``seed``."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < k:
        if name in PAIR_RADIUS:
            r = PAIR_RADIUS[name] * np.sqrt(rng.uniform(size=2))
            a = rng.uniform(0, 2 * np.pi, size=2)
            pq = np.stack([r * np.cos(a), r * np.sin(a)], 1)
        else:
            pq = rng.uniform(-0.9, 0.9, size=(2, 2))
        if np.linalg.norm(pq[1] - pq[0]) >= 0.2:
            out.append(pq)
    return np.asarray(out)


def run_peer(peer: str, python: str | None, job: dict) -> dict:
    """Run the worker in the peer's interpreter; ``{"skipped": reason}`` if it cannot."""
    python = python or os.environ.get(PEER_ENV[peer])
    if not python:
        return {"skipped": f"no interpreter given (--{peer}-python or ${PEER_ENV[peer]})"}
    if not Path(python).exists():
        return {"skipped": f"interpreter {python} does not exist (create the venv as the "
                f"docstring of benchmarks/peers.py says)"}
    env = {**os.environ, **ONE_THREAD}
    try:
        proc = subprocess.run([python, str(WORKER_FILE), peer],
                              input=json.dumps(job), capture_output=True, text=True,
                              env=env, timeout=3600, check=False)
    except subprocess.TimeoutExpired:
        return {"skipped": f"{peer} worker timed out after an hour"}
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-3:]
        return {"skipped": f"{peer} worker failed (exit {proc.returncode}): "
                + " | ".join(tail)}
    return json.loads(proc.stdout)


def project_rows(m: Any, pairs: np.ndarray, with_log: bool) -> list[dict]:
    """The project's methods on ``pairs``, in the same row format as the peers."""
    import inspect

    import solvers

    n_task = m.task.segments
    methods: list[tuple[str, str, str, Any]] = [
        ("solve_geodesic", f"task size, {n_task} segments", "path",
         lambda s, g: solvers.solve_geodesic(m, s, g, n_task)),
        ("solve_geodesic", "256 segments", "path",
         lambda s, g: solvers.solve_geodesic(m, s, g, 256)),
        ("distance", "rtol 1e-8 (default)", "value", lambda s, g: solvers.distance(m, s, g)),
    ]
    has_tol = "tol" in inspect.signature(solvers.solve_geodesic).parameters
    if has_tol:
        methods.append(("solve_geodesic", "tol=1e-7", "value",
                        lambda s, g: solvers.solve_geodesic(m, s, g, tol=1e-7)))
    if with_log:
        methods.append(("log_map", "defaults (Newton shooting from distance)", "log",
                        lambda s, g: solvers.log_map(m, s, g)))
    rows = []
    for method, setting, kind, fn in methods:
        _, setup, _ = timed(lambda fn=fn: fn(pairs[0, 0], pairs[0, 1]))
        per = []
        for s, g in pairs:
            out, sec, err = timed(lambda s=s, g=g, fn=fn: fn(s, g))
            rec: dict[str, Any] = {"seconds": sec, "error": err}
            if out is not None:
                rec["converged"] = bool(out.converged)
                if kind == "path":
                    rec["path"] = out.points.tolist()
                elif kind == "log":
                    rec["velocity"] = out.velocity.tolist()
                    rec["length"] = out.length
                elif method == "distance":
                    rec["length"] = out.distance
                    rec["status"] = out.status.label
                else:  # solve_geodesic(tol=): the estimate of the continuum length
                    est = getattr(out, "length_estimate", None)
                    rec["length"] = out.length if est is None else est
                    rec["error_estimate"] = getattr(out, "error_estimate", None)
            per.append(rec)
        rows.append({"peer": "project", "method": method, "setting": setting, "kind": kind,
                     "setup": setup, "per_pair": per})
    if not has_tol:
        rows.append({"peer": "project", "method": "solve_geodesic", "setting": "tol=1e-7",
                     "skipped": "solve_geodesic has no tol= parameter yet (issue 14 part 3 "
                                "not landed)"})
    return rows


def poincare_velocity(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Closed-form initial velocity of the geodesic from x to y on [0, 1] (Poincare disk):
    the Moebius map z = (u + zx) / (1 + conj(zx) u) sends the diameter
    u(t) = tanh(t d / 2) w / |w| to it, so v = d / 2 (1 - |x|^2) w / |w| with
    w = (zy - zx) / (1 - conj(zx) zy)."""
    zx, zy = complex(*x), complex(*y)
    w = (zy - zx) / (1 - zx.conjugate() * zy)
    d = math.acosh(1 + 2 * float(np.sum((x - y) ** 2)) / ((1 - x @ x) * (1 - y @ y)))
    v = d / 2 * (1 - abs(zx) ** 2) * w / abs(w)
    return np.array([v.real, v.imag])


def project_exp_rows(m: Any, pairs: np.ndarray, vel: np.ndarray) -> list[dict]:
    import solvers

    fn = lambda k: solvers.exp_map(m, pairs[k, 0], vel[k])  # noqa: E731
    _, setup, _ = timed(lambda: fn(0))
    per = []
    for k in range(len(pairs)):
        out, sec, err = timed(lambda k=k: fn(k))
        per.append({"seconds": sec, "error": err,
                    **({} if out is None else {"point": out.point.tolist(),
                                               "converged": out.converged,
                                               "status": out.status.label})})
    return [{"peer": "project", "method": "exp_map", "setting": "defaults (DOP853, 1e-13)",
             "kind": "exp", "setup": setup, "per_pair": per}]


def score(m: Any, pairs: np.ndarray, rows: list[dict], exact: np.ndarray | None) -> None:
    """Add ``length``, ``failed`` and ``err`` to every per-pair record of ``rows``."""
    import solvers

    k = len(pairs)
    for row in rows:
        for i, rec in enumerate(row.get("per_pair", [])):
            s, g = pairs[i]
            why = rec.get("error")
            length = rec.get("length")
            if why is None and row["kind"] == "path" and rec.get("path") is not None:
                pts = np.asarray(rec["path"], dtype=np.float64)
                if not np.all(np.isfinite(pts)):
                    why = "non-finite path"
                elif not np.all(m.domain.contains(pts, tol=1e-9)):
                    why = "path leaves the domain"
                elif max(np.max(np.abs(pts[0] - s)), np.max(np.abs(pts[-1] - g))) > 1e-9:
                    why = "path does not join the pair"
                else:
                    length = float(np.sum(m.segment_length(pts[:-1], pts[1:], 8,
                                                           check=False)))
            if why is None and row["kind"] == "log" and rec.get("velocity") is not None:
                v = np.asarray(rec["velocity"], dtype=np.float64)
                if not np.all(np.isfinite(v)):
                    why = "non-finite velocity"
                else:
                    length = float(m.F(s, v))
                    try:
                        e = solvers.exp_map(m, s, v)
                        miss = float(np.max(np.abs(e.point - g))) if e.converged else math.inf
                    except Exception as err:  # e.g. a velocity into a refused region
                        miss, why = math.inf, f"exp refused: {err}"
                    rec["miss"] = miss
                    if why is None and miss > MISS_TOL:
                        why = f"misses the goal by {miss:.1e}"
            if why is None and row["kind"] == "exp" and rec.get("point") is not None:
                pt = np.asarray(rec["point"], dtype=np.float64)
                if not np.all(np.isfinite(pt)):
                    why = "non-finite point"
                else:
                    length = float(np.max(np.abs(pt - g)))  # the endpoint error
            if why is None and rec.get("converged") is False:
                why = f"not converged ({rec.get('status', 'status')})"
            if why is None and (length is None or not math.isfinite(length)):
                why = "no length"
            rec["length"], rec["failed"] = length, why
    best = np.full(k, np.inf)
    if exact is None:
        for row in rows:
            for i, rec in enumerate(row.get("per_pair", [])):
                upper = row["kind"] == "path" or row["method"] == "distance"
                if upper and rec["failed"] is None:
                    best[i] = min(best[i], rec["length"])
    ref = exact if exact is not None else best
    for row in rows:
        for i, rec in enumerate(row.get("per_pair", [])):
            if rec["failed"] is not None:
                rec["err"] = None
            elif row["kind"] == "exp":
                rec["err"] = rec["length"]
            else:
                rec["err"] = (rec["length"] - ref[i]) / ref[i]


def summarise(name: str, rows: list[dict], exact: bool | None) -> list[str]:
    """Table lines of one section (``exact`` None: the exp section)."""
    head = (f"{'peer':<10} {'method':<20} {'setting':<46} {'time/pair':>10} {'setup':>8} "
            f"{'med |err|':>9} {'max |err|':>9} {'max miss':>8} {'fail':>5}")
    what = ("relative to the exact distance" if exact else
            "length vs the shortest found (relative)" if exact is not None else
            "|exp(x, v) - y|_max with v the closed-form initial velocity of the geodesic "
            "from x to y")
    lines = [f"== {name}: error = {what}", head, "-" * len(head)]
    for row in rows:
        peer = row.get("peer", "?")
        if "skipped" in row:
            lines.append(f"{peer:<10} {row.get('method', ''):<20} {row.get('setting', ''):<46} "
                         f"skipped: {row['skipped']}")
            continue
        per = row["per_pair"]
        secs = np.array([r["seconds"] for r in per])
        errs = np.array([abs(r["err"]) for r in per if r["err"] is not None])
        fails = [r["failed"] for r in per if r["failed"] is not None]
        med = f"{np.median(errs):9.1e}" if errs.size else f"{'-':>9}"
        mx = f"{np.max(errs):9.1e}" if errs.size else f"{'-':>9}"
        ok_miss = [r["miss"] for r in per if r.get("miss") is not None and r["failed"] is None]
        miss = f"{max(ok_miss):8.1e}" if ok_miss else f"{'-':>8}"
        lines.append(f"{peer:<10} {row['method']:<20} {row['setting'][:46]:<46} "
                     f"{_ms(np.median(secs)):>10} {_ms(row.get('setup', 0.0)):>8} {med} {mx} "
                     f"{miss} {len(fails):>2}/{len(per)}")
        longer = int(np.sum(np.array([r["err"] for r in per if r["err"] is not None]) > 1e-3))
        if longer and exact is not None:
            lines.append(f"{'':<10}   {longer} pair(s) more than 1e-3 longer than "
                         + ("d" if exact else "the shortest found")
                         + ": another (local) geodesic")
        if fails:
            kinds: dict[str, int] = {}
            for f in fails:
                key = f.split(" by ")[0] if f.startswith("misses") else f[:60]
                kinds[key] = kinds.get(key, 0) + 1
            misses = [r["miss"] for r in per if r.get("miss") is not None
                      and r["failed"] is not None and math.isfinite(r["miss"])]
            by = f" (max miss {max(misses):.1e})" if misses else ""
            lines.append(f"{'':<10}   failures: "
                         + "; ".join(f"{v} x {k}" for k, v in kinds.items()) + by)
    return lines


def _ms(sec: float) -> str:
    if sec < 1e-3:
        return f"{sec * 1e3:.3f} ms"
    return f"{sec * 1e3:.1f} ms" if sec < 1 else f"{sec:.2f} s"


# ----------------------------------------------------------------------------------------
# throughput (issue 21)
# ----------------------------------------------------------------------------------------
def _energies(m: Any, paths: np.ndarray) -> np.ndarray:
    """``sum C**2`` of paths ``(K, n+1, 2)``; infinite where a path is not finite, leaves
    the domain (1e-9) or misses its pair."""
    out = np.full(len(paths), np.inf)
    for k, p in enumerate(paths):
        if np.all(np.isfinite(p)) and np.all(m.domain.contains(p, tol=1e-9)):
            out[k] = float(np.sum(m.cost(p[:-1], p[1:], check=False) ** 2))
    return out


def _timed_solve(fn: Any) -> tuple[Any, float, float]:
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def _quality(e: np.ndarray, best: np.ndarray) -> str:
    rel = (e - best) / best
    ok = np.isfinite(rel)
    worst = f"{np.max(rel[ok]):.1e}" if ok.any() else "-"
    return (f"{np.sum(rel <= 1e-4):>5} {np.sum(rel <= 1e-6):>5} {np.sum(rel > 1e-3):>5} "
            f"{np.sum(~ok):>4}  worst {worst}")


def throughput(args: Any, ap: Any) -> None:
    """The throughput section: see the module docstring."""
    import finsler
    import solvers
    from solvers.seeding.plans import SeedPlan

    K, Q = args.throughput_pairs, min(args.quality_pairs, args.throughput_pairs)
    if K < 1 or args.reference_rounds < 0 or args.repeats < 1:
        ap.error("--throughput-pairs and --repeats must be >= 1, --reference-rounds >= 0")
    sizes = sorted({int(x) for x in args.batch_sizes.split(",") if x.strip()})
    head = (f"{'method':<44} {'pairs':>5} {'wall/pair':>10} {'CPU/pair':>9} {'setup':>8} "
            f"{'<=1e-4':>6} {'<=1e-6':>5} {'>1e-3':>5} {'fail':>4}")
    for name, n in (("matsumoto", 64), ("randers", 16)):
        m = finsler.get_metric(name)
        pairs = make_pairs(name, m, K, args.seed)
        warm = make_pairs(name, m, 2, args.seed + 99)
        solvers.solve_batch(m, warm, n, workers=1, progress=False)  # lowering, graph
        runs = [_timed_solve(lambda m=m, pairs=pairs, n=n: solvers.solve_batch(
            m, pairs, n, workers=1, progress=False)) for _ in range(args.repeats)]
        res = runs[0][0]
        wall = float(np.median([r[1] for r in runs]))
        cpu = float(np.median([r[2] for r in runs]))
        ours = np.array([r.energy for r in res])
        methods = {k: sum(r.method == k for r in res) for k in ("newton", "ipopt", "none")}
        rows = [("project solve_batch (batched Newton)", K, wall, cpu, 0.0, ours)]
        check = np.stack([make_pairs(name, m, 8, args.seed + 2)[:, 0],
                          np.random.default_rng(args.seed + 1).normal(size=(8, 2))], 1)
        job = {"metric": name, "task": "throughput", "pairs": pairs.tolist(), "segments": n,
               "check": check.tolist(), "repeats": args.repeats,
               "params": {"randers": {"wind": list(WIND)},
                          "matsumoto": {"height": HEIGHT}}[name]}
        fx = run_peer("finslerax", args.finslerax_python, job)
        notes = [f"project: {methods['newton']} pairs by Newton, {methods['ipopt']} finished "
                 f"by IPOPT; largest residual {max(r.residual for r in res):.1e}"]
        if "skipped" in fx:
            notes.append(f"finslerax skipped: {fx['skipped']}")
        else:
            fe = (_energies(m, np.asarray(fx["paths"])) if fx.get("paths") is not None
                  else np.full(K, np.inf))
            rows.append(("finslerax GaussNewton, vmap over the batch", K, fx["seconds"],
                         fx["cpu"], fx["setup"], fe))
            truth = m.F(check[:, 0], check[:, 1])
            gap = float(np.max(np.abs(np.asarray(fx["check"]) - truth) / truth))
            notes.append(f"finslerax {fx['version']}: its F equals the project's to "
                         f"{gap:.1e}; compile time in 'setup'")
        print(f"== throughput: {name}, {n} segments, {K} fresh pairs (seed {args.seed}), "
              "one thread")
        if name == "randers":
            d = m.distance(pairs[:, 0], pairs[:, 1])
            print(f"{'method':<44} {'pairs':>5} {'wall/pair':>10} {'CPU/pair':>9} "
                  f"{'setup':>8} {'max |L-d|/d':>12} {'fail':>4}")
            for label, k, w, c, st, e in rows:
                lengths = np.full(K, np.inf)
                if label.startswith("project"):
                    lengths = np.array([r.length for r in res])
                elif not np.all(np.isinf(e)):
                    p = np.asarray(fx["paths"])
                    lengths = np.array([np.sum(m.cost(q[:-1], q[1:], check=False))
                                        if np.isfinite(ei) else np.inf
                                        for q, ei in zip(p, e, strict=True)])
                err = np.abs(lengths - d) / d
                fin = np.isfinite(err)
                print(f"{label:<44} {k:>5} {_ms(w / k):>10} {_ms(c / k):>9} {_ms(st):>8} "
                      f"{np.max(err[fin]) if fin.any() else float('nan'):>12.1e} "
                      f"{np.sum(~fin):>4}")
        else:
            best = np.min(np.stack([r[5] for r in rows]), 0)
            print(head)
            for label, k, w, c, st, e in rows:
                print(f"{label:<44} {k:>5} {_ms(w / k):>10} {_ms(c / k):>9} {_ms(st):>8} "
                      f"{_quality(e, best)}")
            print(f"-- the first {Q} pairs, against the best of every run below:")
            sub = pairs[:Q]
            ref_rows = [(label, e[:Q]) for label, _, _, _, _, e in rows]
            old, w_old, c_old = _timed_solve(lambda m=m, sub=sub, n=n: solvers.solve_batch(
                m, sub, n, workers=1, progress=False, method="ipopt"))
            ref_rows.append(("project IPOPT default (landed code)", np.array(
                [r.energy for r in old])))
            notes.append(f"IPOPT default: {_ms(w_old / Q)} wall, {_ms(c_old / Q)} CPU per "
                         "pair")
            for seed in range(args.reference_rounds):
                plan = SeedPlan(bulges=(0.05, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0), random=60,
                                graph=True, seed=seed, coarse=None, polish=30,
                                polish_scale=0.03 * (1 + seed % 3))
                wide = solvers.solve_batch(m, sub, n, seeds=plan, workers=1, progress=False)
                ref_rows.append((f"wide multistart {seed} (reference)",
                                 np.array([r.energy for r in wide])))
            best_q = np.min(np.stack([e for _, e in ref_rows]), 0)
            for label, e in ref_rows:
                print(f"{label:<44} {Q:>5} {'':>10} {'':>9} {'':>8} {_quality(e, best_q)}")
        for t in notes:
            print(f"   {t}")
        print(f"-- project time per pair against the batch size ({name}, {n} segments)")
        for b in sizes:
            if b > K:
                continue
            reps = [_timed_solve(lambda m=m, pairs=pairs, n=n, b=b: solvers.solve_batch(
                m, pairs[:b], n, workers=1, progress=False)) for _ in range(args.repeats)]
            w = float(np.median([r[1] for r in reps]))
            c = float(np.median([r[2] for r in reps]))
            print(f"   batch {b:>5}: {_ms(w / b):>9} wall, {_ms(c / b):>9} CPU per pair")
        print(flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", choices=("geomstats", "finslerax"), help=argparse.SUPPRESS)
    ap.add_argument("--pairs", type=int, default=10, help="pairs per metric (default 10)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--metrics", default=",".join(SECTIONS),
                    help="sections to run (default all): " + ",".join(SECTIONS))
    ap.add_argument("--geomstats-python", default=None,
                    help="python of a venv with geomstats 2.8 (numpy<2, autograd); default "
                         "$GEOMSTATS_PYTHON (see this file's docstring to create it)")
    ap.add_argument("--finslerax-python", default=None,
                    help="python of a venv with finslerax 1.1 and jax[cpu]; default "
                         "$FINSLERAX_PYTHON")
    ap.add_argument("--throughput", action="store_true",
                    help="the throughput section instead (see the docstring)")
    ap.add_argument("--throughput-pairs", type=int, default=1000)
    ap.add_argument("--quality-pairs", type=int, default=100)
    ap.add_argument("--reference-rounds", type=int, default=3,
                    help="wide multistarts in the Matsumoto reference (default 3)")
    ap.add_argument("--batch-sizes", default="1,10,100,1000")
    ap.add_argument("--repeats", type=int, default=3,
                    help="timed runs per throughput row; the median is printed (default 3)")
    ap.add_argument("--json", type=Path, help="also write every per-pair record here")
    args = ap.parse_args()
    if args.worker:  # the old way to run a worker: still accepted
        from peer_workers import worker_main

        worker_main(args.worker)
        return
    if args.pairs < 1:
        ap.error("--pairs must be >= 1")
    for k, v in ONE_THREAD.items():
        os.environ.setdefault(k, v)
    import torch

    import finsler

    torch.set_num_threads(1)
    if args.throughput:
        throughput(args, ap)
        return
    names = [s.strip() for s in args.metrics.split(",") if s.strip()]
    unknown = set(names) - set(SECTIONS)
    if unknown:
        ap.error(f"unknown metrics {sorted(unknown)}; choose from {','.join(SECTIONS)}")
    report: dict[str, Any] = {"pairs": args.pairs, "seed": args.seed, "metrics": {}}
    t_start = time.perf_counter()
    for name in names:
        metric_name = "poincare" if name == "exp" else name
        m = bump_metric() if name == "bump" else finsler.get_metric(metric_name)
        pairs = make_pairs(metric_name, m, args.pairs, args.seed)
        rng = np.random.default_rng(args.seed + 1)
        check = np.stack([make_pairs(metric_name, m, 8, args.seed + 2)[:, 0],
                          rng.normal(size=(8, 2))], 1)
        truth = m.F(check[:, 0], check[:, 1])
        job: dict[str, Any] = {"metric": metric_name, "pairs": pairs.tolist(),
                               "check": check.tolist(), "segments": m.task.segments,
                               "params": {"poincare": {}, "bump": BUMP,
                                          "randers": {"wind": list(WIND)},
                                          "matsumoto": {"height": HEIGHT}}[metric_name]}
        if name == "exp":
            vel = np.stack([poincare_velocity(s, g) for s, g in pairs])
            job.update(task="exp", velocities=vel.tolist())
            rows = project_exp_rows(m, pairs, vel)
        else:
            rows = project_rows(m, pairs, with_log=name != "matsumoto")
        notes = []
        for peer in SECTIONS[name]:
            res = run_peer(peer, getattr(args, f"{peer}_python"), job)
            if "skipped" in res:
                rows.append({"peer": peer, "method": "(all)", "setting": "",
                             "skipped": res["skipped"]})
                continue
            gap = float(np.max(np.abs(np.asarray(res["check"]) - truth) / truth))
            notes.append(f"{peer} {res['version']}: its F equals the project's F to {gap:.1e} "
                         "(max relative, 8 sample points)")
            for r in res["rows"]:
                r["peer"] = peer
                rows.append(r)
        exact = (m.distance(pairs[:, 0], pairs[:, 1]) if m.provides("distance") else None)
        score(m, pairs, rows, exact)
        title = "poincare, exp map" if name == "exp" else name
        kind = None if name == "exp" else exact is not None
        lines = summarise(title, rows, kind) + [f"   {t}" for t in notes]
        print("\n".join(lines) + "\n", flush=True)
        report["metrics"][name] = {"pairs": pairs.tolist(), "rows": rows, "notes": notes,
                                   "exact": None if exact is None else exact.tolist()}
    total = time.perf_counter() - t_start
    print(f"{len(names)} sections x {args.pairs} pairs in {total:.0f} s (one thread each)")
    if args.json:
        finsler.atomic_write_text(args.json, json.dumps(report), "--json")


if __name__ == "__main__":
    main()
