"""Polishing in rounds (``SeedPlan.polish_rounds``, issue 45): every round of the batched
solve perturbs the best row found so far, round 0 is the one-round polish unchanged, and
the rows of later rounds are named and counted as polish."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import finsler
import solvers.newton.driver as batched
from finsler import Euclidean, InputError
from solvers import SeedPlan
from solvers.newton.driver import _best, solve_pairs_batched
from solvers.seeding.plans import seed_family

PAIRS = np.array([[[0.0, 0.0], [1.0, 0.5]], [[-0.5, 0.2], [0.7, -0.4]]])


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_polish_rounds_must_be_a_positive_integer(bad) -> None:
    with pytest.raises(InputError, match="polish_rounds"):
        SeedPlan(polish_rounds=bad)


def test_polish_rounds_not_in_the_repr() -> None:
    # benchmarks/ground_truth.py keys its cached multistarts by repr(plan)
    assert "polish_rounds" not in repr(SeedPlan(polish_rounds=3))
    assert SeedPlan(polish_rounds=3) != SeedPlan()


def test_rounds_name_count_and_reach_the_closed_form() -> None:
    m, n = Euclidean(2), 8
    plan = SeedPlan(bulges=(), graph=False, coarse=None, polish=2, polish_rounds=3,
                    polish_scale=0.05, seed=3)
    s = solve_pairs_batched(m, PAIRS, n, plan)
    tail = s.final.names[len(s.first):]
    assert tail == ["straight~p0", "straight~p1"] * 2 + ["straight~p1.0", "straight~p1.1"] * 2 \
        + ["straight~p2.0", "straight~p2.1"] * 2
    assert {seed_family(nm) for nm in tail} == {"polish"}
    assert s.final.pair[len(s.first):].tolist() == [0, 0, 1, 1] * 3
    assert s.levels[-1]["polish"] and s.levels[-1]["solved"].tolist() == [6, 6]
    assert s.stats["levels"][-1]["rows"] == 12
    # every polishing row was perturbed (took iterations) and came back to the line
    assert (s.final.iterations[len(s.first):] > 0).all()
    line = np.sum(np.diff(PAIRS, axis=1)[:, 0] ** 2, axis=1) / n  # |g - s|^2 / n
    np.testing.assert_allclose(s.final.energy, line[s.final.pair], rtol=1e-9)
    assert s.iterations.tolist() == sum(lv["iterations"] for lv in s.levels).tolist()


def test_round_0_is_the_one_round_polish() -> None:
    m, n = Euclidean(2), 8
    one = SeedPlan(bulges=(0.3,), graph=False, coarse=None, polish=3, polish_scale=0.1)
    a = solve_pairs_batched(m, PAIRS, n, one)
    b = solve_pairs_batched(m, PAIRS, n, dataclasses.replace(one, polish_rounds=2))
    k = len(a.final)
    assert b.final.names[:k] == a.final.names
    np.testing.assert_array_equal(b.final.points[:k], a.final.points)
    assert len(b.final) == k + 3 * len(PAIRS)


def test_each_round_perturbs_the_best_row_so_far(monkeypatch) -> None:
    """On Matsumoto (near-equal local minima), the base of every round's perturbations is
    the lowest row solved before that round, and the answer is never above one round's."""
    m = finsler.get_metric("matsumoto")
    pairs = finsler.sample_pairs(m, 100, 424242)[[41, 50, 93]]
    plan = dataclasses.replace(SeedPlan.default(m, "newton"), polish=3, polish_rounds=3)
    calls: list[np.ndarray] = []
    real = batched.perturbed_batch

    def spy(metric, points, *args, **kwargs):
        calls.append(np.array(points))
        return real(metric, points, *args, **kwargs)

    monkeypatch.setattr(batched, "perturbed_batch", spy)
    s = solve_pairs_batched(m, pairs, 64, plan)
    assert len(calls) == plan.polish * plan.polish_rounds  # one call per row per round
    per_round = plan.polish * len(pairs)
    start = len(s.final) - plan.polish_rounds * per_round
    for r in range(plan.polish_rounds):
        before = s.final.take(np.arange(start + r * per_round))
        best = _best(before, len(pairs))
        for j in range(plan.polish):
            np.testing.assert_array_equal(calls[r * plan.polish + j], before.points[best])
    # not vacuous: on these pairs a round moved the base (it found a lower row)
    assert any(not np.array_equal(calls[r * plan.polish], calls[0])
               for r in range(1, plan.polish_rounds))
    monkeypatch.setattr(batched, "perturbed_batch", real)
    once = solve_pairs_batched(m, pairs, 64, dataclasses.replace(plan, polish_rounds=1))
    e3, e1 = s.final.energy[s.best], once.final.energy[once.best]
    assert (e3 <= e1 * (1 + 1e-12)).all()


def test_polish_at_polishes_on_the_ladder_and_carries_the_answer_up() -> None:
    """SeedPlan(polish_at=64) on a 16 -> 64 -> 256 ladder: the polish rows are solved at 64
    segments, between the ladder's levels, none at 256; every row at 256 is carried up, and
    the answer's energy is that of its own points. Without
    ``polish_at`` (or with it at or above the final size) the polish is at the final
    size."""
    m = finsler.get_metric("matsumoto")
    plan = SeedPlan(bulges=(0.3,), random=2, graph=False, coarse=16, factor=4, polish=3,
                    polish_rounds=2, polish_scale=0.15, polish_at=64)
    assert plan.polish_size(256) == 64 and plan.polish_size(64) == 64
    assert plan.polish_size(16) == 16 and SeedPlan(polish_at=8, coarse=16).polish_size(64) == 16
    assert dataclasses.replace(plan, polish_at=None).polish_size(256) == 256
    s = solve_pairs_batched(m, PAIRS[:1] * 0.8, 256, plan)
    sizes = [(lv["segments"], bool(lv.get("polish"))) for lv in s.levels]
    assert sizes == [(16, False), (64, False), (64, True), (256, False)]
    # the final rows are carried up: from 16 (``@16``) or a polish row of 64 (``~p..@64``)
    assert s.final.points.shape[1] == 257
    assert all(nm.endswith("@16") or ("~p" in nm and nm.endswith("@64"))
               for nm in s.final.names)
    best = s.best[0]
    pts = s.final.points[best]
    costs = np.asarray(m.path_costs(pts[None]))[0]
    assert s.final.energy[best] == pytest.approx(float(np.sum(costs**2)), rel=1e-10)
    at_end = solve_pairs_batched(m, PAIRS[:1] * 0.8, 256,
                                 dataclasses.replace(plan, polish_at=256))
    assert [lv["segments"] for lv in at_end.levels if lv.get("polish")] == [256]
    with pytest.raises(InputError, match="polish_at"):
        SeedPlan(polish_at=1)
