"""Distance fields (`solvers.distance_field`): accuracy against closed forms and the exact
solver, time, and scikit-fmm on the same grid.

Measurements, one thread, CPU time (``time.process_time``):

1. **Closed forms, 2-D** (Poincare, Randers, Euclidean, Minkowski, sphere): relative error
   at the nodes farther than 0.05 from the source (3 seeded sources, pooled), median and
   99th percentile at the default resolution and at twice it, and their ratio.
2. **poincare-slab, 3-D**: the same at the default resolution and at 1.5x.
3. **scikit-fmm** (second order, ``travel_time`` with speed ``(1 - |x|**2) / 2``) and the
   field on the same 201 x 201 grid over [-1, 1]^2 (Poincare disk of radius 0.999), errors
   at the nodes with ``|x| < 0.75``; needs the ``bench`` extra (scikit-fmm).
4. **Car-like** on ``--car-pairs`` fresh pairs (``sample_pairs(carlike, K, --car-seed)``):
   the field's value at the goal over the best-known length (the lower energy of the
   default globally seeded solve and the field-seeded one), and the backtracked geodesic
   polished by one exact solve (no other seeds) against the best-known energy.
5. **distance_matrix** on ``--matrix-points`` Matsumoto points: CPU, and on
   ``--matrix-sample`` sampled entries the relative difference from the exact solver's
   continuum length (``solve_geodesic(..., tol=1e-6)``'s ``length_estimate``).

Usage::

    python benchmarks/distance_field.py [--car-pairs 10] [--matrix-points 50] [--skip ...]

Writes ``benchmarks/results/distance-fields/distance_field-DATE.md``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from results_file import ResultsFile, markdown_table  # noqa: E402

import solvers  # noqa: E402
from finsler.pairs import sample_pairs  # noqa: E402
from finsler.registry import get_metric  # noqa: E402
from solvers.fields.field import DEFAULT_RESOLUTION  # noqa: E402


def rel_errors(f: solvers.DistanceField, keep: np.ndarray | None = None,
               radius: float = 0.05) -> np.ndarray:
    pts = f.grid.points()
    ok = (f.grid.inside.ravel() & np.isfinite(f.values.ravel())
          & (np.linalg.norm(pts - f.source, axis=1) > radius))
    if keep is not None:
        ok &= keep
    exact = f.metric.distance(np.repeat(f.source[None], ok.sum(), 0), pts[ok])
    return np.abs(f.values.ravel()[ok] - exact) / exact


def sources(m, k: int, seed: int, shrink: float = 0.7) -> np.ndarray:
    return m.domain.sample(k, np.random.default_rng(seed)) * shrink


def closed_forms(out: ResultsFile, names: list[str], dim: int, factor: float) -> None:
    rows = []
    for name in names:
        m = get_metric(name)
        base = DEFAULT_RESOLUTION[dim]
        errs = {}
        cpu = {}
        for res in (base, round(factor * base)):
            e, c = [], []
            for s in sources(m, 3, 11):
                c0 = time.process_time()
                f = solvers.distance_field(m, s, res, error_estimate=False)
                c.append(time.process_time() - c0)
                e.append(rel_errors(f))
            errs[res] = np.concatenate(e)
            cpu[res] = float(np.median(c))
        (r1, e1), (r2, e2) = errs.items()
        row = [name, r1, f"{np.median(e1):.2e}", f"{np.percentile(e1, 99):.2e}",
               f"{cpu[r1]:.2f}", r2, f"{np.median(e2):.2e}", f"{np.percentile(e2, 99):.2e}",
               f"{cpu[r2]:.2f}", f"{np.median(e2) / np.median(e1):.2f}"]
        print(row, flush=True)
        rows.append(row)
    out.add(f"## Closed forms, {dim}-D (3 sources, errors pooled, nodes > 0.05 from the "
            "source; field alone, no error estimate)\n",
            markdown_table(["metric", "cells", "median", "p99", "CPU s/field", "cells",
                            "median", "p99", "CPU s/field", "median ratio"], rows))


def scikit_fmm(out: ResultsFile, repeats: int = 5) -> None:
    try:
        import skfmm
    except ImportError:
        out.add("## scikit-fmm\n", "scikit-fmm is not installed (the `bench` extra).")
        return
    m = get_metric("poincare", radius=0.999)
    box = (np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    s = np.array([0.1, -0.2])
    x = np.linspace(-1, 1, 201)
    X, Y = np.meshgrid(x, x, indexing="ij")
    r2 = X**2 + Y**2
    keep = (r2.ravel() < 0.75**2)
    # scikit-fmm: the source node inside the zero level set, speed 1 / conformal factor
    phi = np.ones_like(X)
    phi[np.argmin(abs(x - s[0])), np.argmin(abs(x - s[1]))] = -1
    phi = np.ma.MaskedArray(phi, r2 >= 0.999**2)
    speed = np.where(r2 < 1, (1 - r2) / 2, 1e-6)
    ts = []
    for _ in range(repeats):
        c0 = time.process_time()
        T = skfmm.travel_time(phi, speed, dx=float(x[1] - x[0]), order=2)
        ts.append(time.process_time() - c0)
    pts = np.stack([X.ravel(), Y.ravel()], -1)
    ok = keep & (np.linalg.norm(pts - s, axis=1) > 0.05) & ~np.ma.getmaskarray(T).ravel()
    ex = m.distance(np.repeat(s[None], ok.sum(), 0), pts[ok])
    e_fmm = np.abs(np.asarray(T).ravel()[ok] - ex) / ex
    rows = [["scikit-fmm (order 2)", f"{np.median(e_fmm):.2e}",
             f"{np.percentile(e_fmm, 99):.2e}", f"{np.median(ts):.4f}"]]
    for est in (False, True):
        tf = []
        for _ in range(3):
            c0 = time.process_time()
            f = solvers.distance_field(m, s, 200, box=box, error_estimate=est)
            tf.append(time.process_time() - c0)
        e = rel_errors(f, keep)
        rows.append([f"distance_field (201 x 201{', + error estimate' if est else ''})",
                     f"{np.median(e):.2e}", f"{np.percentile(e, 99):.2e}",
                     f"{np.median(tf):.4f}"])
    for r in rows:
        print(r, flush=True)
    out.add("## Poincare against scikit-fmm, same 201 x 201 grid over [-1, 1]^2, "
            "|x| < 0.75, source (0.1, -0.2)\n",
            markdown_table(["method", "median rel. error", "p99", "CPU s (median)"], rows))


def carlike(out: ResultsFile, k: int, seed: int, resolution: tuple[int, ...],
            stencil: tuple[int, ...]) -> None:
    m = get_metric("carlike")
    pairs = sample_pairs(m, k, seed)
    n = m.task.segments
    c0 = time.process_time()
    default = solvers.solve_batch(m, pairs, n, workers=1, progress=False)
    cpu_default = (time.process_time() - c0) / k
    rows = []
    ratios, within, cpus = [], 0, []
    for i, (s, g) in enumerate(pairs):
        c0 = time.process_time()
        f = solvers.distance_field(m, s, resolution, stencil=stencil, error_estimate=False)
        cpu = time.process_time() - c0
        geo = f.geodesic(g, exact=True, segments=n)
        e_best = min(default[i].energy, geo.exact.energy)
        length_best = float(np.sqrt(n * e_best))  # equal segment costs at the optimum
        ratio = f(g) / length_best
        gap = geo.exact.energy / e_best - 1
        gap_default = default[i].energy / e_best - 1
        ok = gap <= 1e-4
        within += ok
        ratios.append(ratio)
        cpus.append(cpu)
        row = [i, f"{cpu:.1f}", f.iterations, f"{f(g):.4f}", f"{length_best:.4f}",
               f"{ratio:.3f}", f"{geo.length:.4f}", f"{geo.exact.length:.4f}", f"{gap:.1e}",
               f"{gap_default:.1e}", geo.exact.status.label]
        print(row, flush=True)
        rows.append(row)
    out.add(f"## Car-like, {k} fresh pairs (`sample_pairs(carlike, {k}, {seed})`), grid "
            f"cells {resolution}, stencil {stencil}\n",
            markdown_table(["pair", "CPU s", "iterations", "field at goal", "best known",
                            "ratio", "backtracked", "exact from it", "its energy gap",
                            "default solve's gap", "status"], rows),
            f"\nmedian ratio {np.median(ratios):.3f}; exact solve from the backtracked path "
            f"within 1e-4 of the best-known energy on {within}/{k}; CPU per field median "
            f"{np.median(cpus):.1f} s, max {max(cpus):.1f} s. Best known: the lower energy of "
            f"the default globally seeded solve (`solve_batch`, {cpu_default:.1f} s CPU per "
            f"pair) and the field-seeded one, {n} segments; its length is sqrt(n E) (equal "
            "segment costs at an energy minimiser).")


def matrix(out: ResultsFile, k: int, sample: int, seed: int, resolution: int | None,
           factor_radius: int | None) -> None:
    m = get_metric("matsumoto")
    pts = sources(m, k, seed, shrink=0.9)
    c0 = time.process_time()
    mat = solvers.distance_matrix(m, pts, resolution=resolution, progress=False,
                                  factor_radius=factor_radius)
    cpu = time.process_time() - c0
    rng = np.random.default_rng(seed + 1)
    rows, rels = [], []
    for _ in range(sample):
        i, j = rng.choice(k, 2, replace=False)
        r = solvers.solve_geodesic(m, pts[i], pts[j], tol=1e-6)
        ref = r.length_estimate if r.length_estimate is not None else r.length
        rel = abs(mat.values[i, j] - ref) / ref
        rels.append(rel)
        rows.append([int(i), int(j), f"{mat.values[i, j]:.5f}", f"{ref:.5f}", f"{rel:.1e}",
                     f"{mat.error[i, j]:.1e}"])
    rels = np.array(rels)
    print("matrix", cpu, np.median(rels), rels.max(), flush=True)
    out.add(f"## distance_matrix, {k} Matsumoto points (seed {seed}, radius <= 0.9), fields "
            f"at resolution {resolution or 'default'}, factor radius "
            f"{factor_radius or 'default'}\n",
            f"CPU {cpu:.1f} s for the {k} fields (with their error estimates), status "
            f"{mat.status.label}; on {sample} sampled entries against the exact solver "
            f"(`solve_geodesic(tol=1e-6)` length estimate): relative difference median "
            f"{np.median(rels):.1e}, max {rels.max():.1e}, within 1e-2 on "
            f"{int((rels <= 1e-2).sum())}/{sample}.\n",
            markdown_table(["i", "j", "matrix", "exact", "rel. diff.", "field's estimate"],
                           rows))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--car-pairs", type=int, default=10)
    p.add_argument("--car-seed", type=int, default=20261207)
    p.add_argument("--car-resolution", default="40,40,24")
    p.add_argument("--car-stencil", default="2,2,1")
    p.add_argument("--matrix-points", type=int, default=50)
    p.add_argument("--matrix-sample", type=int, default=30)
    p.add_argument("--matrix-seed", type=int, default=5)
    p.add_argument("--matrix-resolution", type=int, default=None)
    p.add_argument("--matrix-factor-radius", type=int, default=None)
    p.add_argument("--skip", nargs="*", default=[],
                   choices=["closed2d", "slab", "fmm", "carlike", "matrix"])
    args = p.parse_args()
    out = ResultsFile("distance_field", title="Distance fields: accuracy and time",
                      claim="distance-fields")
    out.add("One thread (OMP/MKL/OpenBLAS = 1); CPU time by `time.process_time`. Relative "
            "errors are |field - exact| / exact.\n")
    if "closed2d" not in args.skip:
        closed_forms(out, ["poincare", "randers", "euclidean", "minkowski", "sphere"], 2, 2.0)
        out.write()
    if "slab" not in args.skip:
        closed_forms(out, ["poincare-slab"], 3, 1.5)
        out.write()
    if "fmm" not in args.skip:
        scikit_fmm(out)
        out.write()
    if "carlike" not in args.skip:
        carlike(out, args.car_pairs, args.car_seed,
                tuple(int(t) for t in args.car_resolution.split(",")),
                tuple(int(t) for t in args.car_stencil.split(",")))
        out.write()
    if "matrix" not in args.skip:
        matrix(out, args.matrix_points, args.matrix_sample, args.matrix_seed,
               args.matrix_resolution, args.matrix_factor_radius)
        out.write()


if __name__ == "__main__":
    main()
