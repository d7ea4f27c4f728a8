"""Learned warm starts for exact solves (issue 11, part 3): ``geodesics solve
--warm-start RUN_OR_ENV`` seeds IPOPT with the policy's paths; the result equals the
globally seeded one on easy pairs; bad sources are refused with clear messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import finsler
import learn
import solvers
from finsler.errors import InputError
from learn.runs import warm_start_paths
from validation.cli import app

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def easy_pairs() -> np.ndarray:
    """Matsumoto pairs with one geodesic (all 8 global seeds agree): three inside the
    convex disk |p| < 0.2887 where F is Finsler, one across the slope. Elsewhere the
    discrete energy has many near-equal local minima and a warm start may end in another
    one (benchmarks/warm_start.py counts them)."""
    return np.array([[[0.1, 0.05], [-0.15, 0.1]], [[-0.2, -0.1], [0.15, 0.12]],
                     [[0.0, 0.2], [0.05, -0.2]], [[0.5, 0.3], [-0.4, 0.2]]])


def test_warm_started_solve_equals_globally_seeded(easy_pairs: np.ndarray) -> None:
    m = finsler.get_metric("matsumoto")
    paths, pol = warm_start_paths("matsumoto", m, easy_pairs)
    assert paths.shape == (4, 65, 2) and pol.metric == m
    # the learned path is not already the geodesic: the solve has work to do
    glob = solvers.solve_batch(m, easy_pairs, workers=1, progress=False)
    warm = solvers.solve_batch(m, easy_pairs, workers=1, progress=False, initial_paths=paths,
                               global_seeds=False)
    for w, g, p in zip(warm, glob, paths):
        assert w.converged and g.converged
        assert w.seeds_tried == 1 < g.seeds_tried
        assert w.energy == pytest.approx(g.energy, rel=1e-6)
        assert np.max(np.abs(w.points - g.points)) < 1e-4
        learned_energy = np.sum(m.path_costs(p[None])[0] ** 2)
        assert learned_energy > g.energy * (1 + 1e-4)


def test_cli_warm_start_matches_the_python_api(tmp_path: Path, easy_pairs: np.ndarray) -> None:
    m = finsler.get_metric("matsumoto")
    pfile = tmp_path / "pairs.npy"
    np.save(pfile, easy_pairs)
    r = CliRunner()
    res = r.invoke(app, ["solve", "--metric", "matsumoto", "--pairs", str(pfile),
                         "--warm-start", "matsumoto", "--workers", "1", "--no-progress",
                         "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["warm_start"]["global_seeds"] is False
    assert doc["warm_start"]["policy"].endswith("matsumoto")
    glob = solvers.solve_batch(m, easy_pairs, workers=1, progress=False)
    for row, g in zip(doc["results"], glob):
        assert row["seeds_tried"] == 1
        assert row["energy"] == pytest.approx(g.energy, rel=1e-6)
    # --keep-global-seeds: the learned path is one more start beside the global seeds
    res = r.invoke(app, ["solve", "--metric", "matsumoto", "--pairs", str(pfile),
                         "--warm-start", "matsumoto", "--keep-global-seeds", "--workers", "1",
                         "--no-progress", "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["warm_start"]["global_seeds"] is True
    for row, g in zip(doc["results"], glob):
        assert row["seeds_tried"] == g.seeds_tried  # the global seeds were solved too
        assert row["energy"] <= g.energy * (1 + 1e-9)
    paths, _ = warm_start_paths("matsumoto", m, easy_pairs[:1])
    both = solvers.solve_batch(m, easy_pairs[:1], workers=1, progress=False,
                               initial_paths=paths, global_seeds=True)[0]
    assert "initial0" in both.seed_energies and len(both.seed_energies) > 1


def test_warm_search_seeds_with_the_route_search(tmp_path: Path,
                                                 easy_pairs: np.ndarray) -> None:
    """--warm-search: the initial paths are the route search's (as the API gives them) and
    the solves reach the globally seeded optima."""
    m = finsler.get_metric("matsumoto")
    paths, pol = warm_start_paths("matsumoto", m, easy_pairs, search=True)
    np.testing.assert_array_equal(paths, pol.search(easy_pairs[:, 0], easy_pairs[:, 1]).paths)
    pfile = tmp_path / "pairs.npy"
    np.save(pfile, easy_pairs)
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--pairs", str(pfile),
                                   "--warm-start", "matsumoto", "--warm-search", "--workers",
                                   "1", "--no-progress", "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["warm_start"]["route_search"] is True
    glob = solvers.solve_batch(m, easy_pairs, workers=1, progress=False)
    for row, g in zip(doc["results"], glob):
        assert row["seeds_tried"] == 1
        assert row["energy"] == pytest.approx(g.energy, rel=1e-6)


def test_bad_warm_start_is_refused_clearly(tmp_path: Path) -> None:
    r = CliRunner()
    base = ["solve", "--metric", "matsumoto", "--start", "0.1,0.2", "--goal", "-0.3,0.1"]
    cases = [
        (["--warm-start", str(tmp_path / "missing_run")], "no such run directory"),
        (["--warm-start", "euclidean"], "no shipped policy for 'euclidean'"),
        (["--warm-start", "carlike"], "policy for 'carlike', not for 'matsumoto'"),
        (["--keep-global-seeds"], "apply to --warm-start"),
        (["--recheck-above", "1.1"], "apply to --warm-start"),
        (["--warm-search"], "apply to --warm-start"),
        (["--warm-start", "matsumoto", "--keep-global-seeds", "--recheck-above", "1.1"],
         "without --keep-global-seeds"),
    ]
    for extra, message in cases:
        res = r.invoke(app, [*base, *extra])
        assert res.exit_code == 2, (extra, res.output)
        assert message in res.output, (extra, res.output)

    # a run trained on other metric parameters than the solve's metric
    cfg = learn.default_config("matsumoto", metric_params={"height": 1.5}, timesteps=1_500,
                               depth=2, hidden=(8,), collection_size=128, minibatch_size=64,
                               epochs=1, eval_every=1, eval_pairs=4, path_energy_weight=0.0)
    learn.train(cfg, tmp_path / "run", progress=False)
    res = r.invoke(app, [*base, "--warm-start", str(tmp_path / "run")])
    assert res.exit_code == 2 and "height=1.5 (solve: 1.0)" in res.output, res.output
    with pytest.raises(InputError, match=r"height=1\.5"):
        warm_start_paths(tmp_path / "run", finsler.get_metric("matsumoto"),
                         np.zeros((1, 2, 2)))
    # the same run warm-starts a solve on its own metric (Python API)
    m15 = finsler.get_metric("matsumoto", height=1.5)
    pairs = np.array([[[0.1, 0.2], [-0.3, 0.1]]])
    paths, _ = warm_start_paths(tmp_path / "run", m15, pairs)
    assert paths.shape == (1, 2**2 + 1, 2)  # the run's depth; the solver resamples to n
    res = solvers.solve_geodesic(m15, pairs[0, 0], pairs[0, 1], initial=(paths[0],),
                                 global_seeds=False)
    ref = solvers.solve_geodesic(m15, pairs[0, 0], pairs[0, 1])
    assert res.converged and res.energy == pytest.approx(ref.energy, rel=1e-6)


def test_recheck_above_resolves_the_untrusted_pairs_globally(tmp_path: Path) -> None:
    """Panda, 20 fresh pairs: --recheck-above R re-solves exactly the pairs whose learned
    energy is above R times the warm optimum, and those end at or below the globally seeded
    energy. R is set in the first gap of more than 1% between consecutive ratios of these
    pairs, from the largest down, so the test re-solves some pairs and keeps others
    whatever policy is shipped (it used fixed values, then the gap after the 3rd largest,
    and retrains outgrew both; the Panda policy shipped before the polish had 1.96, 1.56,
    1.18, then 1.14x; today's has 1.13 then 1.12 as its 3rd and 4th)."""
    m = finsler.get_metric("panda-pole")
    pairs = finsler.sample_pairs(m, 21, 777)[1:]
    pfile = tmp_path / "pairs.npy"
    np.save(pfile, pairs)
    r = CliRunner()
    base = ["solve", "--metric", "panda-pole", "--pairs", str(pfile), "--warm-start",
            "panda-pole", "--workers", "1", "--no-progress", "--json"]
    warm = json.loads(r.invoke(app, base).output)
    # the flags, computed by hand: learned energy (same n) over the warm optimum
    paths, _ = warm_start_paths("panda-pole", m, pairs)
    ratio = np.sum(m.path_costs(paths) ** 2, axis=1) / np.array(
        [row["energy"] for row in warm["results"]])
    top = np.sort(ratio)[::-1]
    gaps = [k for k in range(1, len(top)) if top[k - 1] > top[k] * 1.01]
    assert gaps, "no clear gap to place the threshold in"
    R = float(top[gaps[0] - 1] + top[gaps[0]]) / 2
    assert R > 1.0
    want = [k for k in range(len(pairs)) if ratio[k] > R]
    res = r.invoke(app, [*base, "--recheck-above", repr(R)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    redo = doc["warm_start"]["rechecked"]
    assert redo == want and 0 < len(redo) < len(pairs)
    glob = solvers.solve_batch(m, pairs[redo], workers=1, progress=False)
    for k, g in zip(redo, glob):
        assert doc["results"][k]["energy"] <= g.energy * (1 + 1e-6)
        assert doc["results"][k]["energy"] <= warm["results"][k]["energy"] * (1 + 1e-9)
    others = [k for k in range(len(pairs)) if k not in redo]
    assert [doc["results"][k]["energy"] for k in others] == [
        warm["results"][k]["energy"] for k in others]
    bad = r.invoke(app, [*base, "--recheck-above", "0.5"])
    assert bad.exit_code == 2 and "ratio >= 1" in bad.output


def test_cli_warm_start_from_a_folder_that_is_no_run_names_the_option(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--start", "0.1,0.2",
                                   "--goal", "0.3,0.1", "--warm-start", str(tmp_path)])
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "--warm-start" in lines[0] and "config.json" in lines[0]
