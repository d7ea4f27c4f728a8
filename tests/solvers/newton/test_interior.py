"""The batched interior point for a metric whose F is not smooth (solvers.newton.interior): on
car-like pairs at small sizes its optima against IPOPT's from the same seeds (a second
method), the KKT residual of its paths (solvers.newton.kkt, computed from the points
alone), iterates inside the domain, honest statuses, and the opt-in routing."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import finsler
import solvers
from finsler import InputError
from solvers import SeedPlan
from solvers.geodesic.pair_solver import resolve_method
from solvers.inputs import domain_scale
from solvers.newton import interior
from solvers.newton.interior import InteriorOptions, covers_interior, interior_energy
from solvers.newton.kkt import kkt_residual
from solvers.seeding.plans import seed_batch
from solvers.status import NewtonStatus
from solvers.transcription import energy_nlp

N = 16


@pytest.fixture(scope="module")
def car() -> finsler.Metric:
    return finsler.get_metric("carlike")


@pytest.fixture(scope="module")
def rows(car: finsler.Metric) -> np.ndarray:
    pairs = np.asarray(finsler.sample_pairs(car, 3, 7))
    names, curves = seed_batch(car, pairs[:, 0], pairs[:, 1], N,
                               SeedPlan(bulges=(0.15, 0.3, 0.45, 0.6, 0.8), random=4))
    keep = [i for i, nm in enumerate(names) if nm == "straight" or nm.startswith("bulge")]
    return curves[:, keep].reshape(-1, N + 1, car.dim)


@pytest.fixture(scope="module")
def solved(car: finsler.Metric, rows: np.ndarray):
    return interior_energy(car, rows, scale=domain_scale(car))


def _energy(m: finsler.Metric, pts: np.ndarray) -> float:
    return float(np.sum(m.path_costs(pts[None], check=False) ** 2))


def test_covers_only_nonsmooth_with_the_hook(car: finsler.Metric) -> None:
    assert covers_interior(car)
    assert not covers_interior(finsler.get_metric("matsumoto"))  # smooth: plain Newton


def test_optima_equal_ipopt_from_the_same_seeds(car: finsler.Metric, rows: np.ndarray,
                                                solved) -> None:
    conv = solved.status == NewtonStatus.CONVERGED
    assert conv.mean() >= 0.8, np.bincount(solved.status)
    nlp = energy_nlp(car, N)
    e_ip = np.full(len(rows), np.inf)
    for i in range(len(rows)):
        pts, st, _, _ = nlp.solve(rows[i])
        if st.converged:
            e_ip[i] = _energy(car, pts)
        if conv[i]:
            # every optimum of the interior point is one for IPOPT too (started there,
            # it finds nothing lower)
            p2, st2, _, _ = nlp.solve(solved.points[i])
            assert st2.converged
            assert _energy(car, p2) >= solved.energy[i] * (1 - 1e-6), i
    both = conv & np.isfinite(e_ip)
    rel = (solved.energy - e_ip) / e_ip
    # both are local methods from the same start: most rows end in the same optimum (on
    # these pairs 18 of 26; the others in neighbouring optima, lower as often as higher)
    assert np.sum(both & (np.abs(rel) <= 1e-6)) >= 0.6 * both.sum()
    # per pair, the lowest optimum of the rows is at least as low as IPOPT's, once rows the
    # interior point did not finish are finished by IPOPT from where it stopped (as the
    # batched solve does)
    final = solved.energy.copy()
    for i in np.flatnonzero(~conv):
        pts, st, _, _ = nlp.solve(solved.points[i])
        final[i] = _energy(car, pts) if st.converged else np.inf
    k = len(rows) // 3
    for p in range(3):
        s = slice(p * k, (p + 1) * k)
        assert np.min(final[s]) <= np.min(e_ip[s]) * (1 + 1e-6), p


def test_reported_energy_is_the_energy_of_the_points(car: finsler.Metric, solved) -> None:
    for i in range(len(solved.energy)):
        assert solved.energy[i] == pytest.approx(_energy(car, solved.points[i]), rel=1e-12)


def test_kkt_residual_small_at_the_solution(car: finsler.Metric, solved) -> None:
    conv = np.flatnonzero(solved.status == NewtonStatus.CONVERGED)
    r = kkt_residual(car, solved.points[conv], domain_scale(car))
    assert np.max(r) <= 1e-6, r
    # and it is a measure that can fail: the seeds themselves are far from optimal
    assert np.all(solved.residual[conv] <= InteriorOptions().tol)


def test_iterates_stay_in_the_domain(car: finsler.Metric, rows: np.ndarray,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # seeds with points pushed onto and beyond the rim: moved strictly inside first
    seeds = rows[:4].copy()
    seeds[:, 1:-1, :2] *= 1.3
    seen = []
    step = interior._State.step

    def checked(self, idx):  # type: ignore[no-untyped-def]
        step(self, idx)
        seen.append(self.P.copy())

    monkeypatch.setattr(interior._State, "step", checked)
    res = interior_energy(car, seeds, scale=domain_scale(car))
    assert seen
    for P in seen:
        assert np.all(car.domain.contains(P.reshape(-1, 3), tol=0.0))
        assert np.all(np.abs(P[..., 2]) < np.pi)
    assert np.all(car.domain.contains(res.points.reshape(-1, 3), tol=0.0))


def test_nonconverged_rows_report_their_status(car: finsler.Metric, rows: np.ndarray) -> None:
    res = interior_energy(car, rows[:3], InteriorOptions(max_iter=2), scale=domain_scale(car))
    assert np.all(res.status == NewtonStatus.MAX_ITERATIONS)
    assert np.all(res.iterations == 2)
    assert np.all(res.residual > InteriorOptions().tol)


def test_bad_input(car: finsler.Metric, rows: np.ndarray) -> None:
    with pytest.raises(InputError, match="paths must have shape"):
        interior_energy(car, rows[:, :, :2])
    with pytest.raises(InputError, match="smooth_square_sx"):
        interior_energy(finsler.get_metric("matsumoto"), np.zeros((1, 5, 2)))
    with pytest.raises(InputError, match="max_iter"):
        InteriorOptions(max_iter=0)
    with pytest.raises(InputError, match="groups must be integers of shape"):
        interior_energy(car, rows, groups=np.zeros(len(rows) - 1, dtype=int))
    with pytest.raises(InputError, match="groups must be integers of shape"):
        interior_energy(car, rows, groups=np.zeros(len(rows)))


def test_routing_is_opt_in(car: finsler.Metric) -> None:
    assert resolve_method(car, "auto") == "ipopt"
    assert resolve_method(car, "newton") == "newton"
    # IPOPT's plan: the lattice field's routes at the final size, then warped copies in
    # rounds; the opt-in path has its own: every seed at 128 segments, uneven rows solved
    # again at equal cost spacing, the best 6 to 256, then 2 rounds of 6 warped copies
    assert SeedPlan.default(car) == SeedPlan.default(car, "ipopt")
    ipopt = SeedPlan.default(car, "ipopt")
    assert ipopt.ladder(256) == [256] and ipopt.field_routes == 6
    assert (ipopt.bulges, ipopt.random, ipopt.graph, ipopt.own) == ((), 0, False, False)
    assert (ipopt.warps, ipopt.warp_rounds) == (6, 6)
    newton = SeedPlan.default(car, "newton")
    assert newton.ladder(256) == [128, 256] and newton.refine_top == 6
    assert newton.equalize == 0.05 and newton.field_routes == 0
    assert (newton.warps, newton.warp_rounds) == (6, 2)


def test_batched_solve_against_ipopt(car: finsler.Metric) -> None:
    """The batched solve (method='newton', its default plan: a ladder 16 -> 32) on a small
    pair against the IPOPT plan's answer (an independent reference): no higher than 1e-4
    above it, a converged status, the energy and KKT residual of its own points."""
    pairs = np.asarray(finsler.sample_pairs(car, 1, 20261208))
    n = 64
    plan = dataclasses.replace(SeedPlan.default(car, "newton"), coarse=16)
    new = solvers.solve_batch(car, pairs, segments=n, workers=1, method="newton", seeds=plan,
                              progress=False)[0]
    ref = solvers.solve_batch(car, pairs, segments=n, workers=1, method="ipopt",
                              progress=False)[0]
    assert new.status.converged and ref.status.converged
    assert ref.method == "ipopt" and [lv["segments"] for lv in new.levels][:3] == [16, 32, 64]
    assert new.energy <= ref.energy * (1 + 1e-4)
    assert new.energy == pytest.approx(_energy(car, new.points), rel=1e-9)
    assert new.residual == pytest.approx(
        float(kkt_residual(car, new.points[None], domain_scale(car))[0]), rel=1e-9, abs=1e-15)


def test_solve_batch_newton_is_a_local_optimum(car: finsler.Metric) -> None:
    pairs = np.asarray(finsler.sample_pairs(car, 2, 11))
    plan = dataclasses.replace(SeedPlan.default(car), bulges=(0.3,), random=1, graph=False,
                               own=False, coarse=None, polish=1)
    res = solvers.solve_batch(car, pairs, segments=N, workers=1, method="newton",
                              seeds=plan, progress=False)
    nlp = energy_nlp(car, N)
    for r in res:
        assert r.status.converged
        # the residual reported is the KKT residual of the points
        assert r.residual == pytest.approx(
            float(kkt_residual(car, r.points[None], domain_scale(car))[0]), rel=1e-9, abs=1e-15)
        # IPOPT started at the answer finds nothing lower (a second method)
        pts, st, _, _ = nlp.solve(r.points)
        assert st.converged
        assert _energy(car, pts) >= r.energy * (1 - 1e-6)


@pytest.mark.slow
def test_default_plan_at_the_task_size_against_ipopt(car: finsler.Metric) -> None:
    """The opt-in default plan at the task size (every seed at 128 segments, the best 6
    carried to 256) on a tuning pair where the earlier plan (seeds at 32, a x2 ladder,
    best 3) and IPOPT's plan (a second method, its own seeds and polish) both end in a
    basin ~1e-3 above: it finds the lower one, a path whose energy is that of its points,
    converged, and IPOPT started at it finds nothing more than 1e-4 lower."""
    pairs = np.asarray(finsler.sample_pairs(car, 20, 20261206))[1:2]
    n = 256
    new = solvers.solve_batch(car, pairs, segments=n, workers=1, method="newton",
                              progress=False)[0]
    ref = solvers.solve_batch(car, pairs, segments=n, workers=1, method="ipopt",
                              progress=False)[0]
    assert new.status.converged and ref.status.converged and ref.method == "ipopt"
    assert [lv["segments"] for lv in new.levels][:2] == [128, 256]
    assert new.energy == pytest.approx(_energy(car, new.points), rel=1e-9)
    assert new.energy <= ref.energy * (1 - 5e-4)
    # IPOPT from the answer: a point 3.3e-5 lower (measured; near-equal discrete minima
    # at the kinks), nothing beyond the benchmark's 1e-4
    pts, st, _, _ = energy_nlp(car, n).solve(new.points)
    assert st.converged and _energy(car, pts) >= new.energy * (1 - 1e-4)


def test_a_pairs_answer_does_not_depend_on_the_other_pairs(car: finsler.Metric) -> None:
    """A pair solved alone, or in a batch with others, gives the same path to the last bit.
    The interior point's rows share array operations; a block solve chosen by how many rows
    of the whole batch run (dense stacks for a few, fields for many: equal only to
    rounding) sent pair 80 of sample_pairs(carlike, 100, 20261214) to a path of length
    10.02 alone and 16.15 beside one other pair, both converged."""
    pairs = np.asarray(finsler.sample_pairs(car, 3, 20261236))
    n = 32
    plan = dataclasses.replace(SeedPlan.default(car, "newton"), graph=False, polish=1)
    batch = solvers.solve_batch(car, pairs, segments=n, workers=1, method="newton",
                                seeds=plan, progress=False)
    for k in range(len(pairs)):
        alone = solvers.solve_batch(car, pairs[k:k + 1], segments=n, workers=1,
                                    method="newton", seeds=plan, progress=False)[0]
        np.testing.assert_array_equal(alone.points, batch[k].points)
        assert alone.best_seed == batch[k].best_seed


def test_uneven_rows_are_solved_again_at_equal_cost_spacing(car: finsler.Metric) -> None:
    """SeedPlan(equalize=0.05): every converged row of the first size whose energy is more
    than 5 % above length**2 / n (uneven segment costs) gets a sibling ``=eq``, solved from
    it resampled at equal cost spacing; the plan's own rows are untouched (solved apart),
    and some siblings end lower than their rows (the point of it).

    The pair: pair 1 of sample_pairs(carlike, 4, 20261236), whose 28 uneven rows (energies
    1.56 to 4.8 x length**2 / n) converge in 39-205 of the 300 iterations. The test first
    ran on sample_pairs(carlike, 2, 20261236). On a later machine (same packages; likely
    the processor, since OpenBLAS picks its kernels by processor), two of that data's three
    uneven rows stopped at the 300-iteration cap, so the test checked the iteration cap and
    not the plan."""
    from solvers.newton.driver import solve_pairs_batched

    pairs = np.asarray(finsler.sample_pairs(car, 4, 20261236))[1:2]
    n = 32
    base = dataclasses.replace(SeedPlan.default(car, "newton"), graph=False, polish=0,
                               restarts=0, equalize=0.0)
    off = solve_pairs_batched(car, pairs, n, base).first
    on = solve_pairs_batched(car, pairs, n, dataclasses.replace(base, equalize=0.05)).first
    k = len(off)
    assert on.names[:k] == off.names
    np.testing.assert_array_equal(on.energy[:k], off.energy[:k])
    length = car.path_costs(off.points, check=False).sum(1)
    uneven = np.flatnonzero(off.ok & (off.energy > 1.05 * length**2 / n))
    assert uneven.size >= 3
    assert on.names[k:] == [f"{off.names[i]}=eq" for i in uneven]
    assert np.all(on.pair[k:] == off.pair[uneven])
    lower = on.ok[k:] & (on.energy[k:] < off.energy[uneven] * (1 - 1e-6))
    assert lower.sum() >= 1
    with pytest.raises(InputError, match="equalize"):
        SeedPlan(equalize=-0.1)


def test_warped_copies_of_the_best_row_reach_a_lower_phase_switch(car: finsler.Metric
                                                                   ) -> None:
    """SeedPlan(warps=6): after the plan's rows, six copies of each pair's best row with
    their points slid along the curve (solvers.seeding.plans.warped_batch) are solved; the
    plan's rows are unchanged, the copies are named ``<best>~w<j>``, and on this pair
    (pair 3 of sample_pairs(carlike, 6, 20261240), 32 segments) one ends more than 1 %
    lower: car-like's discrete minima differ by the segment where the path changes phase,
    which sliding the points moves (random perturbations of the same size do not reach
    it: polish=6 at 0.05 stays above)."""
    from solvers.newton.driver import solve_pairs_batched

    pairs = np.asarray(finsler.sample_pairs(car, 6, 20261240))[3:4]
    n = 32
    base = dataclasses.replace(SeedPlan.default(car, "newton"), graph=False, polish=0,
                               restarts=0, equalize=0.0, coarse=None, warps=0)
    off = solve_pairs_batched(car, pairs, n, base)
    on = solve_pairs_batched(car, pairs, n, dataclasses.replace(base, warps=6, warp_rounds=1))
    k = len(off.final)
    assert on.final.names[:k] == off.final.names
    np.testing.assert_array_equal(on.final.energy[:k], off.final.energy[:k])
    best = off.final.names[off.best[0]]
    assert on.final.names[k:] == [f"{best.split('~')[0]}~w{j}" for j in range(6)]
    e_off = off.final.energy[off.best[0]]
    warped = np.where(on.final.ok[k:], on.final.energy[k:], np.inf)
    assert warped.min() < e_off * (1 - 1e-2)
    assert on.final.energy[on.best[0]] == warped.min()
    polished = solve_pairs_batched(car, pairs, n, dataclasses.replace(
        base, polish=6, polish_scale=0.05))
    assert polished.final.energy[polished.best[0]] > e_off * (1 - 1e-3)


def test_ipopt_answers_are_warped_in_rounds_until_one_lowers_nothing(car: finsler.Metric
                                                                     ) -> None:
    """The IPOPT path with SeedPlan(warps=6): after IPOPT's solves, six warped copies of
    the pair's answer are solved by IPOPT from its warm options, round after round from
    the best so far; on this pair (pair 3 of sample_pairs(carlike, 6, 20261240), 32
    segments) they end more than 0.3 % below the answer without them and become the
    result (named ``<seed>~w<round>.<j>``), its energy the sum of the squared
    ``path_costs`` of its points (recomputed here), inside the domain. The solves before
    the warps are those of the plan without them; the rounds stop at the cap or after a
    round that lowered nothing (whose six rows are then all at or above the best)."""
    pairs = np.asarray(finsler.sample_pairs(car, 6, 20261240))[3:4]
    n = 32
    base = dataclasses.replace(SeedPlan.default(car, "ipopt"), field_routes=0, warps=0,
                               bulges=(0.3,))
    off = solvers.solve_batch(car, pairs, n, seeds=base, method="ipopt", workers=1,
                              progress=False)[0]
    on = solvers.solve_batch(car, pairs, n, seeds=dataclasses.replace(base, warps=6,
                                                                      warp_rounds=6),
                             method="ipopt", workers=1, progress=False)[0]
    assert not any(lv.get("warp") for lv in off.levels)
    assert on.converged and on.method == "ipopt"
    assert on.energy < off.energy * (1 - 3e-3)
    assert on.best_seed.startswith(off.best_seed.split("~")[0] + "~w")
    costs = np.asarray(car.path_costs(on.points[None]))[0]
    assert on.energy == pytest.approx(float(np.sum(costs ** 2)), rel=1e-12)
    assert np.all(car.domain.contains(on.points, tol=1e-9))

    def counts(levels: list[dict]) -> list[tuple]:
        return [(lv["segments"], lv["solved"], lv["iterations"]) for lv in levels]

    assert counts(on.levels[:-1]) == counts(off.levels)
    for name, e in off.seed_energies.items():
        assert on.seed_energies[name] == e or (np.isnan(e) and np.isnan(on.seed_energies[name]))
    warped = {k: v for k, v in on.seed_energies.items() if "~w" in k}
    rounds = sorted({int(k.split("~w")[1].split(".")[0]) for k in warped})
    assert on.levels[-1]["warp"] and on.levels[-1]["solved"] == len(warped) == 6 * len(rounds)
    assert rounds == list(range(len(rounds))) and min(warped.values()) == on.energy
    if len(rounds) < 6:  # stopped: its last round lowered nothing
        last = [v for k, v in warped.items() if k.split("~w")[1].startswith(f"{rounds[-1]}.")]
        assert min(v for v in last if np.isfinite(v)) >= on.energy * (1 - 1e-9)
    assert on.iterations > off.iterations


def test_other_first_barriers_end_in_other_basins(car: finsler.Metric) -> None:
    """SeedPlan(barriers=(100,)): the plan's own seeds solved again from 100x the interior
    point's first barrier parameter, named ``<seed>%mu100``, beside the plan's rows (which
    are unchanged); on this pair (pair 3 of sample_pairs(carlike, 6, 20261240), 32
    segments) one of them ends more than 1 % below every row of the plan's own barrier,
    and each is the solve of InteriorOptions(mu0=100) from its seed (a second call)."""
    from solvers.newton.driver import BatchOptions, solve_pairs_batched

    pairs = np.asarray(finsler.sample_pairs(car, 6, 20261240))[3:4]
    n = 32
    base = dataclasses.replace(SeedPlan.default(car, "newton"), graph=False, polish=0,
                               restarts=0, equalize=0.0, coarse=None, warps=0)
    off = solve_pairs_batched(car, pairs, n, base).final
    on = solve_pairs_batched(car, pairs, n, dataclasses.replace(base, barriers=(100.0,))).final
    k = len(off)
    assert on.names[:k] == off.names
    np.testing.assert_array_equal(on.energy[:k], off.energy[:k])
    assert on.names[k:] == [f"{nm}%mu100" for nm in off.names]
    e_off = np.where(off.ok, off.energy, np.inf).min()
    e_on = np.where(on.ok[k:], on.energy[k:], np.inf)
    assert e_on.min() < e_off * (1 - 1e-2)
    # the rows are those of the plan's own solve with mu0 = 100 (independent call)
    ref = solve_pairs_batched(car, pairs, n, base,
                              opts=BatchOptions(interior=InteriorOptions(mu0=100.0))).final
    np.testing.assert_array_equal(on.energy[k:], ref.energy)
    for bad in ((1.0,), (0.0,), (np.inf,), [100.0], (True,)):
        with pytest.raises(InputError, match="barriers"):
            SeedPlan(barriers=bad)


