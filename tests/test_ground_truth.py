"""benchmarks/ground_truth.py's bookkeeping (issue 45): a default run in parts joins back
in pair order or is refused, and the graph build's helpers equal what they replace."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

import finsler
from solvers.seeding import GraphSeeder, _unique

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import ground_truth


def _part(tmp: Path, a: int, b: int, k: int = 6, **over: object) -> Path:
    rec = {"metric": "poincare", "K": k, "seed": 5, "N": 32, "a": a, "b": b,
           "energy": [float(10 * a + j) for j in range(b - a)],
           "converged": [True] * (b - a), "best_seed": [f"s{a + j}" for j in range(b - a)],
           "seeds": [1] * (b - a), "disagree": [False] * (b - a),
           "wall": 2.0 * (a + 1), "cpu": 1.0 * (a + 1), **over}
    p = tmp / f"part{a}-{b}.json"
    p.write_text(json.dumps(rec))
    return p


def test_parts_join_in_pair_order(tmp_path: Path) -> None:
    paths = [_part(tmp_path, 4, 6), _part(tmp_path, 0, 4)]  # given out of order
    rec = ground_truth.merge_parts(paths, "poincare", 6, 5, 32, 6)
    assert rec["best_seed"] == [f"s{i}" for i in range(6)]
    assert rec["energy"] == [0.0, 1.0, 2.0, 3.0, 40.0, 41.0]
    # the time per pair is weighted by the pairs of each part: (4 * 1 + 2 * 5) / 6
    assert rec["cpu"] == pytest.approx(14.0 / 6.0)
    # the first pairs only
    rec4 = ground_truth.merge_parts(paths[1:], "poincare", 6, 5, 32, 4)
    assert len(rec4["energy"]) == 4


@pytest.mark.parametrize("bad", [
    lambda t: [_part(t, 0, 3), _part(t, 4, 6)],             # a gap
    lambda t: [_part(t, 0, 4), _part(t, 3, 6)],             # an overlap
    lambda t: [_part(t, 0, 4)],                             # short of K
    lambda t: [_part(t, 0, 4), _part(t, 4, 6, seed=6)],     # another seed
    lambda t: [_part(t, 0, 4), _part(t, 4, 6, N=64)],       # another size
])
def test_parts_that_do_not_cover_the_pairs_are_refused(tmp_path: Path, bad) -> None:
    with pytest.raises(SystemExit, match="--merge"):
        ground_truth.merge_parts(bad(tmp_path), "poincare", 6, 5, 32, 6)


def test_unique_equals_numpy() -> None:
    rng = np.random.default_rng(3)
    for keys in (rng.integers(0, 50, 400), rng.integers(-5, 5, 1), np.array([], np.int64)):
        assert np.array_equal(_unique(keys), np.unique(keys))


def test_lattice_nodes_are_the_lattices() -> None:
    m = finsler.get_metric("carlike")
    spacing = (0.25, 0.25, np.pi / 4)
    assert np.array_equal(GraphSeeder.lattice_nodes(m, spacing),
                          GraphSeeder.lattice(m, spacing, (1, 1, 1)).nodes)
