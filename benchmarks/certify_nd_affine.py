"""How fast the cell-by-cell proof of a 3-D potential tightens with the cell's width, for
a potential whose gradient is AFFINE in the cell (a quadratic, P2, element) — the
measurement behind the next step of issue 46's 3-D bar (gap 1e-2).

The proof of :mod:`solvers.certificates.nd.certificate` needs, on every cell ``Z`` and direction
``w``, an upper bound of ``H(z) = p(z) . w - F(z, w)`` over ``z`` in ``Z``. Two ways are
compared on cells of width ``h`` (cubes), each against the largest of 4000 sampled values
of ``H`` (the truth, from below):

* **decoupled**: the largest ``p(v) . w`` over the cube's corners minus an enclosure of
  ``min_Z F(., w)`` (what the vertex-covector proof and the P1 element's rows do): the
  covector and the metric are bounded independently, so the bound loses ``|grad_z F| h``,
  FIRST order in ``h``;
* **affine**: one affine-arithmetic enclosure of ``H`` itself
  (:func:`finsler.enclosures.affine.enclose_affine`), where ``p(z)`` and ``F(z, w)`` share the noise
  symbols of ``z``, so their first-order variations cancel and the loss is SECOND order.

Cells: centres ``c`` drawn in the domain, ``p(z)`` the gradient of the exact distance from
a drawn point ``x0`` (closed form, central differences) linearised at ``c``, ``w`` the
direction maximising ``p(c) . w / F(c, w)`` among 2000 drawn ones. The over-estimates are
relative to ``F(c, w)`` (the scale of the dual constraint ``p . w <= F``); ``order`` is
``log2`` of the ratio between successive widths (1: first order, 2: second order).

Run: ``python benchmarks/certify_nd_affine.py [--cells 12] [--seed 20261223]``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import casadi as ca
from results_file import ResultsFile, markdown_table

import finsler
from finsler.enclosures.affine import enclose_affine
from finsler.lowering import lower

WIDTHS = (0.15, 0.075, 0.0375, 0.01875)


def _grad(m: finsler.Metric, x0: np.ndarray, z: np.ndarray, e: float = 1e-5) -> np.ndarray:
    eye = np.eye(z.size)
    return np.array([(m.distance(x0, z + e * eye[i])[0] - m.distance(x0, z - e * eye[i])[0])
                     / (2 * e) for i in range(z.size)])


def cell_case(m: finsler.Metric, rng: np.random.Generator) -> dict[str, list[float]]:
    """Relative over-estimates (affine, decoupled) per width for one drawn cell."""
    lo, hi = (np.asarray(b, float) for b in m.domain.bounds())
    while True:  # a centre and a source well inside the domain, apart
        c, x0 = rng.uniform(lo, hi, (2, lo.size)) * 0.8
        if (np.all(m.domain.contains(np.stack([c, x0]), tol=0.0))
                and np.linalg.norm(c - x0) > 0.3):
            break
    p0 = _grad(m, x0, c)
    q = np.array([(_grad(m, x0, c + 1e-4 * e) - _grad(m, x0, c - 1e-4 * e)) / 2e-4
                  for e in np.eye(lo.size)]).T
    dirs = rng.normal(size=(2000, lo.size))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    fc = np.array([float(m.F(c, w)) for w in dirs])
    k = int(np.argmax(dirs @ p0 / fc))
    w, scale = dirs[k], fc[k]
    z = ca.SX.sym("z", lo.size)
    h_expr = ca.dot(ca.DM(p0) + ca.DM(q) @ (z - ca.DM(c)), ca.DM(w)) - m.F_sx(z, ca.DM(w))
    h_fn, h_num = lower(ca.Function("H", [z], [h_expr])), ca.Function("Hn", [z], [h_expr])
    f_fn = lower(ca.Function("Fw", [z], [m.F_sx(z, ca.DM(w))]))
    out: dict[str, list[float]] = {"affine": [], "decoupled": []}
    corners = np.array(np.meshgrid(*[(-1.0, 1.0)] * lo.size)).reshape(lo.size, -1).T
    for h in WIDTHS:
        blo, bhi = (c - h / 2)[None], (c + h / 2)[None]
        sample = c + h * rng.uniform(-0.5, 0.5, (4000, lo.size))
        truth = float(np.max(h_num(sample.T).full()))
        aff = float(np.asarray(enclose_affine(h_fn, blo, bhi)[0].hi)[0])
        f_low = float(np.asarray(enclose_affine(f_fn, blo, bhi)[0].lo)[0])
        dec = max(float((p0 + q @ (v * h / 2)) @ w) for v in corners) - f_low
        out["affine"].append((aff - truth) / scale)
        out["decoupled"].append((dec - truth) / scale)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--metric", default="poincare-slab")
    ap.add_argument("--cells", type=int, default=12)
    ap.add_argument("--seed", type=int, default=20261223)
    ap.add_argument("--no-results-file", action="store_true")
    args = ap.parse_args()
    m = finsler.get_metric(args.metric)
    rng = np.random.default_rng(args.seed)
    t0, c0 = time.perf_counter(), time.process_time()
    cases = [cell_case(m, rng) for _ in range(args.cells)]
    rows = []
    for way in ("decoupled", "affine"):
        over = np.array([c[way] for c in cases])  # (cells, widths)
        med = np.median(over, axis=0)
        order = [float("nan")] + [float(np.log2(a / b)) for a, b in itertools.pairwise(med)]
        for h, mm, mx, o in zip(WIDTHS, med, over.max(axis=0), order):
            rows.append([way, f"{h:g}", f"{mm:.2e}", f"{mx:.2e}",
                         "-" if np.isnan(o) else f"{o:.2f}"])
    table = markdown_table(["bound", "width h", "median over-estimate / F(c, w)",
                            "max", "order (log2 of successive medians)"], rows)
    print(table)
    print(f"{args.cells} cells, CPU {time.process_time() - c0:.1f} s, "
          f"wall {time.perf_counter() - t0:.1f} s")
    if not args.no_results_file:
        out = ResultsFile(f"certify_nd_affine-{args.metric}",
                          title="3-D cell proof: affine (correlated) against decoupled bounds",
                          claim="certify-nd")
        out.add(f"Metric `{args.metric}`, {args.cells} cells drawn with seed {args.seed}; "
                "p(z) the closed-form distance's gradient linearised at the cell's centre "
                "(what a P2 element's gradient is), w the dual maximiser at the centre; "
                "truth = largest of 4000 sampled H. See the script's docstring.", table)
        print(out.write())


if __name__ == "__main__":
    main()
