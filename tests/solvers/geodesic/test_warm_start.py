"""Learned warm starts for exact solves (issue 11, part 3; issue 47): ``geodesics solve
--warm-start RUN_OR_ENV`` adds the policy's path of each pair as one more start of the
batched solve, beside the global seeds, so it never ends worse than the default (checked on
pairs where the learned path alone does end worse); the Python API still solves a learned
path alone (``global_seeds=False``); bad sources are refused with clear messages."""

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
from finsler import InputError
from learn import warm_start_paths
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


def test_cli_warm_start_adds_one_start_beside_the_global_seeds(
        tmp_path: Path, easy_pairs: np.ndarray) -> None:
    m = finsler.get_metric("matsumoto")
    pfile = tmp_path / "pairs.npy"
    np.save(pfile, easy_pairs)
    r = CliRunner()
    base = ["solve", "--metric", "matsumoto", "--pairs", str(pfile), "--warm-start",
            "matsumoto", "--workers", "1", "--no-progress", "--json"]
    res = r.invoke(app, base)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["warm_start"]["global_seeds"] is True
    # deprecated (issue 47): the default is as good and faster; the message says so
    assert "--warm-start is deprecated" in res.stderr and "never worse" in res.stderr
    assert doc["warm_start"]["policy"].endswith("matsumoto")
    glob = solvers.solve_batch(m, easy_pairs, workers=1, progress=False)
    for row, g in zip(doc["results"], glob):
        assert row["seeds_tried"] == g.seeds_tried  # the global seeds were solved too
        assert row["energy"] <= g.energy * (1 + 1e-9)
    # the learned path is a row of the same batch (the Python API the command calls)
    paths, _ = warm_start_paths("matsumoto", m, easy_pairs[:1])
    both = solvers.solve_batch(m, easy_pairs[:1], workers=1, progress=False,
                               initial_paths=paths, global_seeds=True)[0]
    assert "initial0" in both.seed_energies and len(both.seed_energies) > 1


def test_warm_start_is_never_worse_where_the_learned_path_alone_is(tmp_path: Path) -> None:
    """Issue 47: on pairs where a solve from the learned path alone (the warm start before
    issue 47) ends in a worse optimum than the default solve, ``--warm-start`` ends at the
    default's optimum or below. The pairs are found, not listed: of 30 fresh Matsumoto pairs
    (seed 777) those where the path alone ends above the default by more than 1e-6 (4 pairs
    with today's policy, by 0.08 % to 9.7 %; the test needs one)."""
    m = finsler.get_metric("matsumoto")
    pairs = finsler.sample_pairs(m, 30, 777)
    paths, _ = warm_start_paths("matsumoto", m, pairs)
    alone = solvers.solve_batch(m, pairs, 64, workers=1, progress=False, initial_paths=paths,
                                global_seeds=False)
    glob = solvers.solve_batch(m, pairs, 64, workers=1, progress=False)
    worse = [k for k in range(len(pairs)) if alone[k].energy > glob[k].energy * (1 + 1e-6)]
    assert worse, "the learned path alone ends at the default optimum on every pair"
    pfile = tmp_path / "pairs.npy"
    np.save(pfile, pairs[worse])
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--pairs", str(pfile),
                                   "--segments", "64", "--warm-start", "matsumoto",
                                   "--workers", "1", "--no-progress", "--json"])
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)["results"]
    for k, row in zip(worse, rows):
        assert row["energy"] <= glob[k].energy * (1 + 1e-9), (k, row["energy"], glob[k].energy)
        assert row["energy"] < alone[k].energy


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
    doc = json.loads(res.stdout)  # (stderr holds the deprecation warning)
    assert doc["warm_start"]["route_search"] is True
    glob = solvers.solve_batch(m, easy_pairs, workers=1, progress=False)
    for row, g in zip(doc["results"], glob):
        assert row["seeds_tried"] == g.seeds_tried
        assert row["energy"] <= g.energy * (1 + 1e-9)


def test_bad_warm_start_is_refused_clearly(tmp_path: Path) -> None:
    r = CliRunner()
    base = ["solve", "--metric", "matsumoto", "--start", "0.1,0.2", "--goal", "-0.3,0.1"]
    cases = [
        (["--warm-start", str(tmp_path / "missing_run")], "no such run directory"),
        (["--warm-start", "euclidean"], "no shipped policy for 'euclidean'"),
        (["--warm-start", "carlike"], "policy for 'carlike', not for 'matsumoto'"),
        (["--warm-search"], "applies to --warm-start"),
    ]
    for extra, message in cases:
        res = r.invoke(app, [*base, *extra])
        assert res.exit_code == 2, (extra, res.output)
        assert message in res.output, (extra, res.output)

    # a run trained on other metric parameters than the solve's metric
    cfg = learn.default_config("matsumoto", metric_params={"height": 1.5}, timesteps=1_500,
                               depth=2, hidden=(8,), collection_size=128, minibatch_size=64,
                               epochs=1, eval_every=1, eval_pairs=4, path_energy_weight=0.0)
    learn.train_run(cfg, tmp_path / "run", progress=False)
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


def test_cli_warm_start_from_a_folder_that_is_no_run_names_the_option(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--start", "0.1,0.2",
                                   "--goal", "0.3,0.1", "--warm-start", str(tmp_path)])
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "--warm-start" in lines[0] and "config.json" in lines[0]
