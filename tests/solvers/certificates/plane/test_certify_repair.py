"""solvers.certificates.plane.repair: the local repair of an LP round's potential, checked against
every row rebuilt densely (``FULL`` of ``helpers.lp_rows``) and the full LP's
optimum by scipy's HiGHS."""

from __future__ import annotations

import numpy as np
import pytest

import solvers.certificates.plane.lp as lp_mod
import solvers.certificates.plane.repair as rep
from solvers.certificates.plane.lp import _solve_lp
from solvers.certificates.plane.repair import repair

from tests.helpers.lp_rows import DIRS, FULL, MESH, NV, K, highs_solve, weights

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


def _optimum(b: np.ndarray) -> np.ndarray:
    return highs_solve(b).x


def _ratio(phi: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (FULL @ phi / b.reshape(-1)).reshape(NV, K)


def _broken(b: np.ndarray) -> tuple[np.ndarray, int]:
    """The optimum at 95 %, with one interior vertex unknown pushed up until rows break."""
    phi = 0.95 * _optimum(b)
    j = int(np.flatnonzero(np.isin(np.arange(MESH.points.shape[0]), MESH.tri))[10])
    assert j not in (0, 1)
    phi[j] += 0.05
    assert _ratio(phi, b).max() > 1.05
    return phi, j


def test_a_pushed_unknown_is_mended_locally_and_every_row_holds() -> None:
    b = weights()
    phi, _ = _broken(b)
    ratio = _ratio(phi, b)
    out = repair(MESH, b.reshape(NV, K), DIRS, phi, ratio, (0, 1))
    assert out is not None
    assert _ratio(out, b).max() <= 1.0 + 1e-9  # every row, rebuilt here
    assert out[0] == phi[0] and out[1] == phi[1]  # the value is kept
    bad = np.unique(np.flatnonzero(ratio.max(axis=1) > 1.0) // 3)
    ring = np.isin(MESH.dofs, MESH.dofs[bad]).any(axis=1)
    moved = np.flatnonzero(out != phi)
    assert moved.size and np.isin(moved, MESH.dofs[ring]).all()  # only the patch moves


def test_nothing_broken_or_too_much_broken_gives_none(monkeypatch: pytest.MonkeyPatch
                                                      ) -> None:
    b = weights()
    good = 0.9 * _optimum(b)
    assert repair(MESH, b.reshape(NV, K), DIRS, good, _ratio(good, b), (0, 1)) is None
    phi, _ = _broken(b)
    monkeypatch.setattr(rep, "REPAIR_MAX_TRIANGLES", 1)
    assert repair(MESH, b.reshape(NV, K), DIRS, phi, _ratio(phi, b), (0, 1)) is None


def test_a_round_short_of_the_target_only_by_broken_rows_is_repaired(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """All vertices exact with 5 directions: the round's potential breaks unsampled rows;
    with the upper bound just above its value the repair lifts the bound from value /
    ratio to a potential that holds every row (checked here), never below; the debug log
    says how long the repair took (clock readings), its largest row ratio and its bound."""
    import logging
    import re

    from tests.helpers.tick_clock import TickClock

    b = weights()
    active = np.zeros((NV, K), bool)
    active[:, [0, 7, 13, 20, 26]] = True
    start = {"exact": np.ones(NV, bool), "active": active}
    monkeypatch.setattr(lp_mod, "REPAIR", False)
    plain = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=start,
                      max_iter=1)
    value = plain["lower"] * plain["ratio"] * (1 + 1e-12)
    assert plain["ratio"] > 1.01
    monkeypatch.setattr(lp_mod, "REPAIR", True)
    monkeypatch.setattr(lp_mod, "time", TickClock())
    caplog.set_level(logging.DEBUG, logger="solvers.certificates.plane.lp")
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=1.001 * value, target=0.05, start=start,
                  max_iter=1)
    msgs = [rec.getMessage() for rec in caplog.records
            if rec.name == "solvers.certificates.plane.lp"]
    got = [re.fullmatch(r"repaired in (\S+) s: max row ratio (\S+) -> bound (\S+)", m)
           for m in msgs]
    got = [g for g in got if g is not None]
    assert len(got) == 1, msgs
    assert got[0][1] == "1.00"  # one clock reading between the repair's start and end
    assert float(got[0][2]) == pytest.approx(r["ratio"], abs=2e-6)
    assert float(got[0][3]) == pytest.approx(r["lower"], abs=2e-8)
    assert len(got[0][2].split(".")[1]) == 6 and len(got[0][3].split(".")[1]) == 8
    assert r["lower"] > plain["lower"] * 1.001
    assert _ratio(r["phi"], b).max() <= 1.0 + 1e-9
    assert r["phi"][1] - r["phi"][0] == pytest.approx(r["lower"], rel=1e-12)
    assert r["lower"] <= value * (1 + 1e-9)
