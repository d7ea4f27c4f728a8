"""Long solver checks on the paper's full evaluation sets (``pytest -m slow``)."""

from __future__ import annotations

import numpy as np
import pytest

import finsler
import solvers
from solvers import Status
from solvers.baseline import adam_energy_baseline

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name, n", [("carlike", 256), ("panda-pole", 32), ("matsumoto", 64)])
def test_exact_ceiling_on_evaluation_set(name: str, n: int) -> None:
    """Every pair of the 100-pair evaluation set: IPOPT success for the energy and the
    min-max solve, no seed below the returned energy, and the exact ceiling of the task
    (min-max max segment cost <= eps) reached on every pair (measured 100/100 each)."""
    m = finsler.get_metric(name)
    pairs = finsler.default_pairs(m, 100)
    results = solvers.solve_batch(m, pairs, n, minmax=True, workers=2, progress=False)
    for r in results:
        assert r.status is Status.SUCCESS
        assert r.minmax.status is Status.SUCCESS
        finite = [e for e in r.seed_energies.values() if np.isfinite(e)]
        assert min(finite) >= r.energy * (1 - 1e-12)
        assert r.minmax.max_segment_cost <= r.max_segment_cost * (1 + 1e-12)
    assert np.mean([r.success(m.task.eps) for r in results]) == 1.0


def test_matsumoto_never_above_adam_on_a_second_pair_set() -> None:
    m = finsler.get_metric("matsumoto")
    pairs = finsler.sample_pairs(m, 100, seed=7)
    ours = np.array([solvers.solve_geodesic(m, s, g, 64).energy for s, g in pairs])
    _, adam, _ = adam_energy_baseline(m, pairs, 64)
    assert np.all(adam >= ours * (1 - 1e-12))


@pytest.mark.parametrize("name", ["poincare", "sphere"])
def test_distance_closed_form_many_pairs(name: str) -> None:
    """500 pairs per curved reference: within 1e-8, estimate bounds the error."""
    m = finsler.get_metric(name)
    pairs = finsler.sample_pairs(m, 500, seed=123)
    exact = m.distance(pairs[:, 0], pairs[:, 1])
    for k, (s, g) in enumerate(pairs):
        r = solvers.distance(m, s, g)
        assert r.converged
        err = abs(r.distance - exact[k])
        assert err <= 1e-8 * exact[k] and err <= r.error_estimate
