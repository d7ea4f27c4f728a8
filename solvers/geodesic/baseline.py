"""The paper authors' way of getting "true" geodesics, kept as a comparison baseline.

Adam on the discrete energy ``sum_i C(p_i, p_{i+1})**2`` from the straight line, for a
fixed number of steps: no convergence test, no global search. It is *not* ground truth
(see STYLE.md, "Avoid" 2); ``benchmarks/solver_speed.py`` and the tests use it to show that
the IPOPT solver with global seeding never ends above it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from finsler.errors import InputError
from finsler.metrics.base import Metric

__all__ = ["adam_energy_baseline"]


def adam_energy_baseline(
    metric: Metric,
    pairs: Any,
    segments: int,
    lr: float = 1e-3,
    steps: int = 1000,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Adam (``lr``, ``steps``) on the energy of ``segments``-segment paths from straight
    lines, all pairs ``(K, 2, dim)`` batched (Adam is elementwise, so this equals one run per
    pair); points are projected into the domain after every step.

    Returns (paths ``(K, n+1, dim)``, energies ``(K,)`` in float64, wall time in seconds).
    """
    import torch

    from solvers.inputs import check_pairs, check_segments

    arr = check_pairs(metric, pairs)
    n = check_segments(metric, segments)
    if not (np.isfinite(lr) and lr > 0) or not isinstance(steps, int) or steps < 0:
        raise InputError(f"need lr > 0 and steps >= 0, got lr={lr!r}, steps={steps!r}")
    t0 = time.perf_counter()
    p = torch.as_tensor(arr, dtype=torch.float64)
    s, g = p[:, 0:1], p[:, 1:2]
    t = torch.linspace(0, 1, n + 1, dtype=torch.float64)[1:-1, None]
    x = (s + t * (g - s)).clone().requires_grad_(True)
    opt = torch.optim.Adam([x], lr=lr)
    for _ in range(steps):
        opt.zero_grad()
        e = (metric.path_costs(torch.cat([s, x, g], 1)) ** 2).sum()
        e.backward()
        opt.step()
        with torch.no_grad():
            x.copy_(metric.domain.project(x))
    path = torch.cat([s, x, g], 1).detach().numpy()
    energy = np.sum(metric.path_costs(path) ** 2, axis=1)
    return path, energy, time.perf_counter() - t0
