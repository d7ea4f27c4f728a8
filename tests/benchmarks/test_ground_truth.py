"""benchmarks/ground_truth.py's bookkeeping (issue 45): a default run in parts joins back
in pair order or is refused, and the graph build's helpers equal what they replace."""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import finsler
from solvers.seeding.graph import GraphSeeder, _unique

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
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


def _fake_run(monkeypatch, tmp_path: Path, e_def, e_ms, converged=None) -> dict:
    """``run_metric`` on 4 Poincaré pairs with the default and the multistart stood in by
    the given energies, the answer store in ``tmp_path``."""
    import answer_store

    monkeypatch.setattr(answer_store, "STORE", tmp_path)
    monkeypatch.setattr(ground_truth, "best_known", lambda *a, **k: {
        "energy": np.asarray(e_ms, float), "converged": np.ones(len(e_ms), bool),
        "families": np.asarray(["straight"] * len(e_ms)),
        "best_seed": np.asarray(["straight"] * len(e_ms)), "cpu": np.zeros(len(e_ms))})
    monkeypatch.setattr(ground_truth, "default_records", lambda *a, **k: {
        "energy": list(e_def), "converged": converged or [True] * len(e_def),
        "best_seed": ["straight"] * len(e_def), "seeds": [1] * len(e_def),
        "disagree": [False] * len(e_def), "wall": 0.0, "cpu": 0.0})
    return ground_truth.run_metric("poincare", len(e_def), 5, 20, 5)


def test_stored_answers_of_another_plan_lower_the_best_known(monkeypatch, tmp_path) -> None:
    """A second plan's answers, kept by an earlier run, join the best known (the gaps are
    against the lowest of all three, computed here by hand); the measured plan's own
    earlier answers are not read as its own (it is solved afresh), but where a rerun ends
    higher they are kept apart (``<label>@<commit> <date>``) and, being valid paths,
    lower the best known; a non-converged answer never lowers it."""
    import answer_store

    monkeypatch.setattr(answer_store, "STORE", tmp_path)
    m = finsler.get_metric("poincare")
    path = answer_store.store_path(m, 5, 4, 2 ** m.task.depth)
    assert path.parent == tmp_path
    meta = {"metric": "poincare", "seed": 5, "K": 4, "N": 2 ** m.task.depth}
    # another plan: lower on pair 1 (converged) and on pair 2 (not converged)
    answer_store.record(path, "other-plan", [9.0, 1.0, 0.5, 9.0], [True, True, False, True],
                        meta)
    # the measured plan's own earlier answers: lower on pair 3 (0.1 against the run's 1.0)
    answer_store.record(path, answer_store.plan_label(m, "auto"), [9.0, 9.0, 9.0, 0.1],
                        [True] * 4, meta)
    e_def, e_ms = [1.0, 2.0, 1.0, 1.0], [1.0, 2.0, 2.0, 1.0]
    r = _fake_run(monkeypatch, tmp_path, e_def, e_ms)
    best = np.array([1.0, 1.0, 1.0, 0.1])
    assert np.allclose(r["gaps"], np.asarray(e_def) / best - 1.0)
    assert r["within_tight"] == 2 and r["worst_pair"] == 3
    assert r["other"]["beat"] == 2  # pairs 1 (the other plan) and 3 (the earlier run)
    # the run kept its default's answers under its label, replacing the stale ones
    answers = answer_store.load(path)["answers"]
    kept = answers[answer_store.plan_label(m, "auto")]
    assert kept["energy"] == e_def and kept["converged"] == [True] * 4
    # ... and kept the stale ones apart (lower on pair 3: they still lower a best known)
    stale = [v for lab, v in answers.items()
             if lab.startswith(answer_store.plan_label(m, "auto") + "@")]
    assert len(stale) == 1 and stale[0]["energy"] == [9.0, 9.0, 9.0, 0.1]


def test_store_keeps_a_part_in_place(tmp_path: Path) -> None:
    """Parts of one label fill their own pairs; pairs not computed read as infinite."""
    import answer_store

    path = tmp_path / "s.json"
    meta = {"metric": "poincare", "seed": 5, "K": 5, "N": 8}
    answer_store.record(path, "x", [3.0, 4.0], [True, True], meta, first=2)
    answer_store.record(path, "x", [1.0], [True], meta, first=0)
    e = answer_store.stored(answer_store.load(path), 5)["x"]
    assert np.array_equal(e, [1.0, np.inf, 3.0, 4.0, np.inf])
    assert answer_store.stored(answer_store.load(path), 5, exclude="x") == {}
    # rerun, lower or equal everywhere: replaced in place, nothing kept apart
    answer_store.record(path, "x", [1.0, 2.0, 3.0, 3.5], [True] * 4, meta, first=0)
    assert list(answer_store.load(path)["answers"]) == ["x"]
    # rerun, higher on pair 2 (or not converged on pair 3): the earlier answers stay apart
    answer_store.record(path, "x", [4.0, 3.0], [True, False], meta, first=2)
    answers = answer_store.load(path)["answers"]
    assert len(answers) == 2
    (apart,) = [lab for lab in answers if lab != "x"]
    assert apart.startswith("x@")
    assert answers[apart]["energy"] == [1.0, 2.0, 3.0, 3.5, None]
    assert np.array_equal(answer_store.stored(answers and answer_store.load(path), 5,
                                              exclude="x")[apart],
                          [1.0, 2.0, 3.0, 3.5, np.inf])


def test_the_run_without_its_warp_rows_is_measured_too(monkeypatch, tmp_path) -> None:
    """The default's answers without its warp rows (solved last) are judged against the
    same best known: here the warps lowered pair 1 (2.0 -> 1.0), so without them 3/4."""
    import answer_store

    monkeypatch.setattr(answer_store, "STORE", tmp_path)
    e_def, e_ms = [1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]
    monkeypatch.setattr(ground_truth, "best_known", lambda *a, **k: {
        "energy": np.asarray(e_ms), "converged": np.ones(4, bool),
        "families": np.asarray(["straight"] * 4), "best_seed": np.asarray(["straight"] * 4),
        "cpu": np.zeros(4)})
    monkeypatch.setattr(ground_truth, "default_records", lambda *a, **k: {
        "energy": e_def, "converged": [True] * 4, "best_seed": ["straight~w2"] * 4,
        "seeds": [1] * 4, "disagree": [False] * 4, "wall": 0.0, "cpu": 0.0,
        "before_warp": [1.0, 2.0, 1.0 + 1e-6, 1.0], "warp_iterations": [10, 20, 10, 0],
        "iterations": [100] * 4, "warp_wall": [1.0, 3.0, 0.0, 0.0]})
    r = ground_truth.run_metric("poincare", 4, 5, 20, 5)
    assert r["within_tight"] == 4
    assert r["warp"] == {"within_tight": 3, "within_loose": 3, "worst_gap": 1.0,
                         "lowered": 1, "share": 0.1, "wall": 1.0}


def test_before_warp_is_the_best_of_the_other_rows() -> None:
    r = types.SimpleNamespace(seed_energies={"graph": 2.0, "graph~w1": 1.0,
                                             "bulge+0.3#0@128~p2": 1.5, "random1": np.nan})
    assert ground_truth._before_warp(r) == 1.5
    r = types.SimpleNamespace(seed_energies={"graph~w0": 1.0, "graph": np.nan})
    assert ground_truth._before_warp(r) == np.inf
