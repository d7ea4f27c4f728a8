import time, dataclasses
import numpy as np
import finsler
from solvers.certify_nd import NDSpec
from solvers.certify_nd_parts import build_cells, point_cloud, lowered_f_grad, cube_directions
from solvers.certify_nd_p2 import P2Cells, verify_p2, lowered_f_joint, _bounds, nodes
from solvers.geodesic import solve_geodesic
m = finsler.get_metric("poincare-slab")
s, g = finsler.sample_pairs(m, 10, 5)[2]
blo, bhi = (np.asarray(b, float) for b in m.domain.bounds())
sol = solve_geodesic(m, s, g, 128)
rng = np.random.default_rng(0)
pts = point_cloud(blo, bhi, np.asarray(sol.points), 0.15, 0.12, 0.6, rng)
pts = np.concatenate([pts, s[None], g[None]])
cells = build_cells(pts, blo, bhi, rng, 0.15)
rel = np.flatnonzero(cells.inside & ~cells.flat)
p2 = P2Cells(cells)
# potential: exact distance from a point behind s
d = (s - g); x0 = s + 0.05 * d / np.linalg.norm(d)
allp = np.concatenate([cells.points, 0.5 * (cells.points[np.sort(p2.cells.simp[:, p2.pairs], axis=2).reshape(-1,2)[:,0]] )])
# values at dofs: vertices and edge midpoints
e = np.sort(cells.simp[:, p2.pairs], axis=2).reshape(-1, 2)
uniq, inv = np.unique(e, axis=0, return_inverse=True)
dofpts = np.concatenate([cells.points, 0.5 * (cells.points[uniq[:, 0]] + cells.points[uniq[:, 1]])])
inside = m.domain.contains(dofpts, tol=0.0)
dofpts_c = np.clip(dofpts, blo, bhi)
# clip to disk
r = np.linalg.norm(dofpts_c[:, :2], axis=1); f = np.minimum(1, 0.699 / np.maximum(r, 1e-12)); dofpts_c[:, :2] *= f[:, None]
phi = np.asarray(m.distance(np.repeat(x0[None], len(dofpts_c), 0), dofpts_c), float).reshape(-1)
gc, H, gerr = p2.affine_gradients(phi, rel)
print("gerr", np.percentile(gerr, [50, 90, 100]))
f_fn, fg_fn = lowered_f_grad(m); fj = lowered_f_joint(m)
x = cells.points[cells.simp[rel]]
# restrict to cells near the path
cen = x.mean(1)
from solvers.certify_nd_parts import distance_to_path
near = distance_to_path(cen, np.asarray(sol.points)) < 0.1
print("near cells", near.sum())
t0 = time.process_time()
ver = verify_p2(fj, fg_fn, x[near], gc[near], H[near], gerr[near], blo, bhi, 1.0, 2e-3, max_depth=8)
print({k: v for k, v in ver.items() if k != "cuts"}, time.process_time() - t0)
print("---- far source")
x0 = s + 0.3 * d / np.linalg.norm(d)
x0[:2] *= min(1, 0.69 / np.linalg.norm(x0[:2]))
phi = np.asarray(m.distance(np.repeat(x0[None], len(dofpts_c), 0), dofpts_c), float).reshape(-1)
gc, H, gerr = p2.affine_gradients(phi, rel)
t0 = time.process_time()
ver = verify_p2(fj, fg_fn, x[near], gc[near], H[near], gerr[near], blo, bhi, 1.0, 2e-3, max_depth=8)
print({k: v for k, v in ver.items() if k != "cuts"}, time.process_time() - t0)
# single-item diagnostics at depth 0: items = near cells x 96 dir boxes
from solvers.certify_nd_parts import face_boxes
wlo0, whi0 = face_boxes(3, 4)
xs = x[near]; T = xs.shape[0]
cell = np.repeat(np.arange(T), len(wlo0)); simp = np.repeat(xs, len(wlo0), 0)
wlo, whi = np.tile(wlo0, (T, 1)), np.tile(whi0, (T, 1))
zlo = np.maximum(simp.min(1), blo); zhi = np.minimum(simp.max(1), bhi)
uh, up, fl = _bounds(fj, fg_fn, cell, simp, zlo, zhi, wlo, whi, xs.mean(1), gc[near], H[near], gerr[near], 1.05)
# sampled truth of H with R=1.05
rng2 = np.random.default_rng(1)
worst = np.argsort(-uh)[:5]
for it in worst:
    t = cell[it]
    lam = rng2.dirichlet(np.ones(4), 3000); z = lam @ simp[it]
    w = rng2.uniform(wlo[it], whi[it], (3000, 3))
    gz = gc[near][t] + (z - xs[t].mean(0)) @ H[near][t].T
    (fv,) = f_fn(z, w); fv = np.asarray(fv).reshape(-1)
    hv = np.einsum("ij,ij->i", gz, w) - 1.05 * fv
    print("item", it, "bound", uh[it], "sampled max", hv.max(), "box", zhi[it]-zlo[it], "w", wlo[it], whi[it], "gerr", gerr[near][t], "|H|", np.abs(H[near][t]).max())
