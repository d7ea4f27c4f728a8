"""Policy-guided route search at generation time: values of C only, never worse than the
policy's own path.

The recursive generation (`learn.Policy.generate`) commits to the actor's midpoint at
every level. Where the policy learned a locally shortest route (round the wrong side of
a hill, a detour on a short pair near the rim of the Matsumoto disk), no later level can
undo that choice. `search_paths` keeps the actor as the generator and lets C decide
between routes:

* at each of the top ``levels`` levels, every sub-pair ``(a, b)`` gets candidate midpoints:
  the actor's mean ``m0``, the coordinate midpoint ``c``, and ``c + r |b - a| u``,
  ``m0 + r |b - a| u`` for the ``radii`` ``r`` and ``directions`` unit vectors ``u`` (2-D:
  evenly spaced angles; n-D: seeded random directions orthogonal to ``b - a``, both
  signs), projected into the domain. Each candidate is completed by the actor's own
  recursive halves down to the task's depth, and the candidate whose completed path has
  the smallest ``sum C`` is kept, among those whose largest segment cost is at most
  ``max(eps, the actor's own completion's)`` (the actor's mean wins ties);
* then ``polish`` sweeps replace each interior point ``x_i`` by the actor's midpoint of its
  neighbours ``(x_i-1, x_i+1)`` where that lowers ``C(x_i-1, x_i) + C(x_i, x_i+1)`` without
  raising the larger of the two above ``eps`` (odd then even indices);
* then ``windows`` sweeps re-generate windows of the path: for window sizes
  ``2**(D-1)`` down to 2 segments, at two offsets (windows start at multiples of the size,
  and half a size later), the actor's own depth-``k`` tree between a window's two end
  points replaces the window where that lowers its cost without raising its largest
  segment above ``eps``. The tree was built from fixed anchors; a window whose ends sit
  elsewhere gets a fresh, often shorter completion;
* then ``equalize`` rounds of `equalize_paths` move the interior points along the
  path so that its segments cost the same: the success criterion bounds the *largest*
  segment cost, and a recursive tree that is off by a little at every level splits the
  path unevenly.

The levels, the polish and the windows compare the true cost of real paths and keep the
policy's choice as a candidate, so before equalizing the path is never longer (in ``sum
C``) than the policy's own path, pair by pair, and succeeds (every segment cost <=
``eps``) wherever the policy's does. Equalizing never raises a path's largest segment cost
(so success at any threshold is never lost) nor its discrete energy ``n * sum C**2``, so
its length stays at most ``sqrt(n * sum C**2)`` of the path it started from. The search
evaluates C (values only, no derivatives: model-free) and the actor; `SearchResult`
counts the evaluations of C per path.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch

import finsler
from finsler.errors import InputError
from finsler.infra.limits import check_number
from finsler.status import Result, SearchStatus, json_ready
from learn.tree import build_tree

__all__ = ["SearchResult", "SearchSpec", "equalize_paths", "search_paths"]

Predict = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]

#: Largest number of float64 coordinates held by one chunk's candidate trees.
CHUNK_FLOATS = 20_000_000


@dataclass(frozen=True)
class SearchSpec:
    """Settings of `search_paths`. The defaults were chosen on tuning pairs never used
    for reporting; the figures are in ``docs/guides/route-search.md`` ("How the defaults
    were chosen") and ``benchmarks/results/policies/route-search-moved.md``."""

    levels: int = 3
    """Top levels of the tree at which candidate midpoints are compared (0: none)."""
    directions: int = 12
    """Unit directions of the candidate offsets (2-D: evenly spaced angles; n-D: half as
    many seeded random directions orthogonal to the pair, both signs)."""
    radii: tuple[float, ...] = (0.1, 0.25, 0.5, 0.75, 1.0)
    """Offsets of the candidates as fractions of the sub-pair's coordinate distance."""
    polish: int = 2
    """Sweeps replacing each interior point by the actor's midpoint of its neighbours
    where that shortens the path (0: none)."""
    windows: int = 3
    """Sweeps of window re-generation after the polish (0: none); each sweep goes through
    window sizes ``2**(D-1)`` down to 2 segments. 3: most of what 6 sweeps gain, at a
    few ms per path."""
    equalize: int = 3
    """Rounds of `equalize_paths` after the polish (0: none). 3: more rounds gained
    nothing on the tuning pairs."""
    seed: int = 0
    """Seed of the random directions (n-D only)."""

    def __post_init__(self) -> None:
        for name, low in (("levels", 0), ("directions", 2), ("polish", 0), ("windows", 0),
                          ("equalize", 0), ("seed", 0)):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < low:
                raise InputError(f"SearchSpec.{name} must be an integer >= {low}, got {val!r}")
        try:
            radii = tuple(float(r) for r in self.radii)
        except (TypeError, ValueError):
            raise InputError(f"SearchSpec.radii must be a sequence of numbers, got "
                             f"{self.radii!r}") from None
        if not all(math.isfinite(r) and r > 0 for r in radii):
            raise InputError(f"SearchSpec.radii must be positive and finite, got {self.radii!r}")
        object.__setattr__(self, "radii", radii)

    @property
    def candidates(self) -> int:
        """Candidate midpoints per sub-pair at a searched level."""
        return 2 + 2 * self.directions * len(self.radii)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "radii": list(self.radii)}


@dataclass
class SearchResult(Result):
    """Paths ``(K, 2**D + 1, dim)`` float64 and the evaluations of C the search made (a
    [`finsler.status.Result`][finsler.status.Result]: ``status`` is a `finsler.status.SearchStatus`,
    ``completed`` when every point is finite)."""

    paths: np.ndarray
    evaluations: int
    """Evaluations of C (values only) over all pairs."""
    wall_time: float = field(default=0.0, kw_only=True)
    """Seconds the search took."""

    @property
    def status(self) -> SearchStatus:  # type: ignore[override]
        """``completed``, or ``not_finite`` if a path holds a non-finite point."""
        finite = bool(np.all(np.isfinite(np.asarray(self.paths, dtype=np.float64))))
        return SearchStatus.COMPLETED if finite else SearchStatus.NOT_FINITE

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: paths (lists; non-finite points ``None``), evaluations,
        evaluations_per_path, status, converged, wall_time."""
        return json_ready({"paths": self.paths, "evaluations": int(self.evaluations),
                           "evaluations_per_path": self.evaluations_per_path,
                           "status": self.status.label, "converged": self.converged,
                           "wall_time": float(self.wall_time)})

    @property
    def evaluations_per_path(self) -> float:
        return self.evaluations / max(len(self.paths), 1)


def _unit_directions(spec: SearchSpec, d: torch.Tensor) -> list[torch.Tensor]:
    """Unit offset directions per sub-pair ``(N, dim)`` for sub-pair vectors ``d``."""
    n, dim = d.shape
    if dim == 1:
        return [torch.ones_like(d), -torch.ones_like(d)]
    if dim == 2:
        ang = 2 * np.pi * np.arange(spec.directions) / spec.directions
        return [torch.tensor([[math.cos(a), math.sin(a)]], dtype=d.dtype).expand(n, 2)
                for a in ang]
    rng = np.random.default_rng(spec.seed)
    raw = torch.as_tensor(rng.standard_normal((max(spec.directions // 2, 1), dim)), dtype=d.dtype)
    dd = (d * d).sum(1, keepdim=True).clamp_min(1e-300)
    out = []
    for r in raw:
        u = r[None] - (d @ r)[:, None] * d / dd  # orthogonal to the pair
        u = u / u.norm(dim=1, keepdim=True).clamp_min(1e-300)
        out += [u, -u]
    return out


def _candidates(metric: finsler.Metric, predict: Predict, a: torch.Tensor, b: torch.Tensor,
                spec: SearchSpec) -> torch.Tensor:
    """Candidate midpoints ``(N, R, dim)`` of sub-pairs ``a``, ``b`` ``(N, dim)``; the
    actor's mean first."""
    m0 = predict(a, b)
    mid = 0.5 * (a + b)
    dist = (b - a).norm(dim=1, keepdim=True)
    cs = [m0, mid]
    for u in _unit_directions(spec, b - a):
        for r in spec.radii:
            step = r * dist * u
            cs += [metric.domain.project(mid + step), metric.domain.project(m0 + step)]
    return torch.stack(cs, 1)


def _costs(metric: finsler.Metric, paths: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """``sum C`` and ``max C`` per path of ``(N, n+1, dim)`` float64 paths."""
    c = np.asarray(metric.path_costs(paths.cpu().numpy(), check=False))
    return c.sum(axis=1), c.max(axis=1)


def _keep(total: np.ndarray, worst: np.ndarray, eps: float) -> np.ndarray:
    """Index per row of ``(N, R)`` costs of the shortest candidate whose largest segment
    cost is at most ``max(eps, that of candidate 0)`` (the policy's own): the search never
    turns a successful path (every segment <= eps) into a failed one. Candidate 0 always
    qualifies; the first minimum wins ties."""
    bound = np.maximum(eps, worst[:, :1])
    return np.argmin(np.where(worst <= bound, total, np.inf), axis=1)


def equalize_paths(metric: finsler.Metric, paths: Any,
                   rounds: int = 3) -> tuple[np.ndarray, int]:
    """Move the interior points of ``paths`` ``(K, n+1, dim)`` along each path towards equal
    segment costs; returns the new float64 paths and the evaluations of C made (values
    only: ``K * n * (rounds + 1)``; none for ``rounds == 0``).

    One round re-samples each path at ``n - 1`` equally spaced values of its cumulative
    cost ``sum C``, the points on the path's own straight pieces (linear in coordinates
    within a piece, its cost taken as spread evenly along it). A path takes the re-sampled
    points only if that lowers or keeps its discrete energy ``n * sum C**2`` and does not
    raise its largest segment cost, and every new point lies in the domain; otherwise it
    is kept as it is. So success (every segment cost <= eps) at any eps is never lost and
    the length stays at most ``sqrt(n * sum C**2)`` of the input (Cauchy-Schwarz). For a
    metric whose C is exactly additive along straight pieces (Euclidean) one round gives
    exactly equal segments."""
    if isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) or rounds < 0:
        raise InputError(f"rounds must be an integer >= 0, got {rounds!r}")
    p = torch.as_tensor(np.array(paths, dtype=np.float64))
    if p.ndim != 3 or p.shape[1] < 2 or p.shape[2] != metric.dim:
        raise InputError(f"paths must have shape (K, n+1, {metric.dim}) with n >= 1, got "
                         f"{tuple(p.shape)}")
    if not bool(torch.isfinite(p).all()):
        raise InputError("paths contain NaN or inf")
    if rounds == 0 or p.shape[1] < 3 or p.shape[0] == 0:
        return p.numpy(), 0
    c = torch.tensor(np.asarray(metric.path_costs(p.numpy(), check=False)), dtype=torch.float64)
    q, evals = _equalize(metric, p, c, rounds)
    return q.numpy(), p.shape[0] * (p.shape[1] - 1) + evals


def _equalize(metric: finsler.Metric, p: torch.Tensor, c: torch.Tensor,
              rounds: int) -> tuple[torch.Tensor, int]:
    """`equalize_paths` on float64 CPU paths ``p`` whose segment costs ``c`` are
    known; returns the paths and the evaluations of C made (``K * n * rounds``)."""
    k, n1, dim = p.shape
    n = n1 - 1
    evals = 0
    frac = torch.arange(1, n, dtype=torch.float64) / n
    for _ in range(rounds):
        cum = torch.cat([torch.zeros((k, 1), dtype=torch.float64), c.cumsum(1)], 1)
        target = cum[:, -1:] * frac  # (K, n-1)
        i = (torch.searchsorted(cum.contiguous(), target.contiguous(), right=True) - 1
             ).clamp(0, n - 1)
        ci = c.gather(1, i)
        f = ((target - cum.gather(1, i)) / ci.clamp_min(1e-300)).clamp(0.0, 1.0)
        a = p.gather(1, i[..., None].expand(-1, -1, dim))
        b = p.gather(1, (i + 1)[..., None].expand(-1, -1, dim))
        q = p.clone()
        q[:, 1:-1] = a + f[..., None] * (b - a)
        inside = torch.tensor(
            np.asarray(metric.domain.contains(q.reshape(-1, dim).numpy()))).reshape(k, n1)
        cn = torch.tensor(np.asarray(metric.path_costs(q.numpy(), check=False)),
                          dtype=torch.float64)
        evals += k * n
        ok = (inside.all(1) & torch.isfinite(cn).all(1)
              & ((cn**2).sum(1) <= (c**2).sum(1)) & (cn.max(1).values <= c.max(1).values))
        p = torch.where(ok[:, None, None], q, p)
        c = torch.where(ok[:, None], cn, c)
    return p, evals


def _regenerate_windows(metric: finsler.Metric, predict: Predict, paths: torch.Tensor,
                        costs: torch.Tensor, size: int, eps: float
                        ) -> tuple[torch.Tensor, torch.Tensor, int]:
    """Replace windows of ``2**size`` segments (starting at multiples of ``2**size``, then
    half a window later) by the actor's depth-``size`` tree between their end points where
    that is shorter and keeps the window's largest segment cost within ``max(eps, its
    old one)``. ``costs`` ``(B, n)`` are the path's segment costs (kept up to date, so a
    window's old cost is never evaluated again); returns the paths, their costs and the
    evaluations of C made (the new trees' segments)."""
    b, n1, dim = paths.shape
    w = 2**size
    evals = 0
    for offset in (0, w // 2):
        first = torch.arange(offset, n1 - w, w, device=paths.device)
        if first.numel() == 0:
            continue
        nw = first.numel()
        idx = first[:, None] + torch.arange(w + 1, device=paths.device)[None]  # (W, w + 1)
        old = paths[:, idx]  # (B, W, w + 1, dim)
        c_old = costs[:, idx[:, :-1]]  # (B, W, w)
        new = build_tree(old[:, :, 0].reshape(-1, dim), old[:, :, -1].reshape(-1, dim), size,
                         predict).reshape(b, nw, w + 1, dim)
        c_new = torch.tensor(np.asarray(metric.path_costs(
            new.reshape(-1, w + 1, dim).cpu().numpy(), check=False)),
            dtype=costs.dtype, device=costs.device).reshape(b, nw, w)
        evals += b * nw * w
        ok = ((c_new.sum(-1) < c_old.sum(-1))
              & (c_new.max(-1).values <= torch.clamp(c_old.max(-1).values, min=eps)))
        paths = paths.clone()
        paths[:, idx[:, 1:-1].reshape(-1)] = torch.where(
            ok[..., None, None], new, old)[:, :, 1:-1].reshape(b, -1, dim)
        costs = costs.clone()
        costs[:, idx[:, :-1].reshape(-1)] = torch.where(
            ok[..., None], c_new, c_old).reshape(b, -1)
    return paths, costs, evals


def _search_chunk(metric: finsler.Metric, predict: Predict, s: torch.Tensor, g: torch.Tensor,
                  depth: int, eps: float, spec: SearchSpec) -> tuple[torch.Tensor, int]:
    b, dim = s.shape
    evals = 0
    pts = torch.stack([s, g], 1)  # points chosen so far: (B, 2**l + 1, dim)
    for level in range(min(spec.levels, depth)):
        rest = depth - level - 1  # depth of each half's completion
        a = pts[:, :-1].reshape(-1, dim)
        z = pts[:, 1:].reshape(-1, dim)
        cs = _candidates(metric, predict, a, z, spec)  # (N, R, dim)
        n, r, _ = cs.shape
        aa = a[:, None].expand(n, r, dim).reshape(-1, dim)
        zz = z[:, None].expand(n, r, dim).reshape(-1, dim)
        mm = cs.reshape(-1, dim)
        full = torch.cat([build_tree(aa, mm, rest, predict),
                          build_tree(mm, zz, rest, predict)[:, 1:]], 1)
        evals += full.shape[0] * (full.shape[1] - 1)
        total, worst = _costs(metric, full)
        best = torch.as_tensor(_keep(total.reshape(n, r), worst.reshape(n, r), eps),
                               device=cs.device)
        chosen = cs[torch.arange(n, device=cs.device), best].reshape(b, -1, dim)
        new = pts.new_empty((b, 2 * pts.shape[1] - 1, dim))
        new[:, 0::2] = pts
        new[:, 1::2] = chosen
        pts = new
    # complete every sub-pair with the actor's recursive halves
    lev = pts.shape[1] - 1
    rest = depth - (lev.bit_length() - 1)
    sub = build_tree(pts[:, :-1].reshape(-1, dim), pts[:, 1:].reshape(-1, dim), rest, predict)
    sub = sub.reshape(b, lev, 2**rest + 1, dim)
    paths = torch.cat([sub[:, :, :-1].reshape(b, -1, dim), pts[:, -1:]], 1)
    for _ in range(spec.polish):
        for first in (1, 2):
            idx = torch.arange(first, paths.shape[1] - 1, 2)
            if idx.numel() == 0:
                continue
            lo, x, hi = paths[:, idx - 1], paths[:, idx], paths[:, idx + 1]
            k = idx.numel()
            flat = [t.reshape(-1, dim) for t in (lo, x, hi)]
            xn = predict(flat[0], flat[2])
            trip_old = torch.stack([flat[0], flat[1], flat[2]], 1)
            trip_new = torch.stack([flat[0], xn, flat[2]], 1)
            old, old_worst = _costs(metric, trip_old)
            new, new_worst = _costs(metric, trip_new)
            evals += 4 * flat[0].shape[0]
            ok = (new < old) & (new_worst <= np.maximum(eps, old_worst))
            take = torch.as_tensor(ok, device=paths.device).reshape(b, k, 1)
            paths[:, idx] = torch.where(take, xn.reshape(b, k, dim), x)
    if not (spec.windows or spec.equalize):
        return paths, evals
    # segment costs of the path, kept up to date by the windows and the equalizing rounds
    costs = torch.tensor(np.asarray(metric.path_costs(paths.cpu().numpy(), check=False)),
                         dtype=torch.float64, device=paths.device)
    evals += b * (paths.shape[1] - 1)
    for _ in range(spec.windows):
        for size in range(depth - 1, 0, -1):  # window of 2**size segments
            paths, costs, e = _regenerate_windows(metric, predict, paths, costs, size, eps)
            evals += e
    if spec.equalize:
        eq, e = _equalize(metric, paths.cpu(), costs.cpu(), spec.equalize)
        paths = eq.to(paths.device)
        evals += e
    return paths, evals


def search_paths(metric: finsler.Metric, predict: Predict, starts: torch.Tensor,
                 goals: torch.Tensor, depth: int, eps: float,
                 spec: SearchSpec | None = None) -> SearchResult:
    """Policy-guided search (module docstring): ``starts``, ``goals`` ``(K, dim)`` float64
    tensors in the domain, ``predict(a, b)`` the actor's projected float64 midpoints, the
    task's success threshold ``eps`` -> paths ``(K, 2**depth + 1, dim)`` and the
    evaluations of C made."""
    check_number(eps, "eps", 0.0, low_open=True)
    spec = spec or SearchSpec()
    if not isinstance(spec, SearchSpec):
        raise InputError(f"search must be a SearchSpec, got {type(spec).__name__}")
    k, dim = starts.shape
    # the candidate trees of one level: R candidates x (2**depth + 2**level + 1) points,
    # a few copies in build_tree
    per_pair = 3 * spec.candidates * (2**depth + 2 ** min(spec.levels, depth) + 1) * dim
    chunk = max(1, CHUNK_FLOATS // max(per_pair, 1))
    out, evals = [], 0
    t0 = time.perf_counter()
    with torch.no_grad():
        for i in range(0, k, chunk):
            p, e = _search_chunk(metric, predict, starts[i:i + chunk].to(torch.float64),
                                 goals[i:i + chunk].to(torch.float64), depth, float(eps),
                                 spec)
            out.append(p)
            evals += e
    return SearchResult(torch.cat(out).cpu().numpy(), evals,
                        wall_time=time.perf_counter() - t0)
