"""Code asks the metrics what they can do (``finsler.list_metrics(provides=..., dim=...)``)
instead of keeping lists of their names."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import finsler
from finsler import InputError

from tests.helpers.metrics.registry_queries import Flat, FlatNoForm, Trained

ROOT = Path(__file__).resolve().parents[2]


def test_list_metrics_filters_by_what_a_metric_provides() -> None:
    finsler.register_metric(Flat)
    finsler.register_metric(FlatNoForm)
    try:
        closed = finsler.list_metrics(provides="distance")
        assert "test-flat-closed" in closed and "test-flat-open" not in closed
        # the registered metrics answer for themselves
        for name in finsler.list_metrics():
            m = finsler.get_metric(name)
            assert (name in closed) == m.provides("distance")
        two = finsler.list_metrics(dim=2)
        assert "carlike" not in two and "panda-pole" not in two and "matsumoto" in two
        assert "matsumoto" not in finsler.list_metrics(convex_everywhere=True)
        assert finsler.list_metrics() == list(finsler.registry._REGISTRY)
        with pytest.raises(InputError):
            finsler.list_metrics(provides="no_such_hook")
    finally:
        finsler.registry.unregister_metric("test-flat-closed")
        finsler.registry.unregister_metric("test-flat-open")


def _name_lists_in(source: str, names: set[str], where: str = "") -> list[str]:
    """List, tuple and set literals holding two or more registered metric names, and dict
    literals with a registered metric name among their keys (a dict keyed by metric names
    is a list of names with data beside it, even with one key: the data belongs on the
    metric, e.g. ``Metric.training``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.List, ast.Tuple, ast.Set)):
            elts = node.elts
        elif isinstance(node, ast.Dict):
            elts = [k for k in node.keys if k is not None]
        else:
            continue
        hits = [e.value for e in elts if isinstance(e, ast.Constant) and e.value in names]
        if len(hits) >= (1 if isinstance(node, ast.Dict) else 2):
            found.append(f"{where}:{node.lineno} {hits}")
    return found


def _name_lists(path: Path, names: set[str]) -> list[str]:
    return _name_lists_in(path.read_text(), names, str(path.relative_to(ROOT)))


def test_no_list_of_metric_names_outside_finsler() -> None:
    names = set(finsler.list_metrics())
    found = []
    for pkg in ("solvers", "learn", "validation"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            found += _name_lists(path, names)
    assert not found, "ask finsler.list_metrics(provides=..., dim=...) instead:\n" + \
        "\n".join(found)


def test_the_scan_catches_dicts_keyed_by_metric_names() -> None:
    # the per-metric dicts the midpoint and Seq configs kept before Metric.training
    old = """
_PAPER_LR = {"matsumoto": 3e-5, "carlike": 1e-6, "panda-pole": 1e-6}
_OURS = {
    "matsumoto": dict(timesteps=100_000_000),
    "carlike": dict(timesteps=400_000_000),
}
_MODEL_FREE = {"matsumoto": dict(epochs=3), "carlike": dict(epochs=2)}
_CYCLES = {"panda-pole": (1077, 1077)}  # learn/pg/config.py's PG schedule, one key
ok = ("matsumoto",)  # one name in a sequence is a lookup, not a list
"""
    found = _name_lists_in(old, set(finsler.list_metrics()), "old")
    assert [f.split()[0] for f in found] == ["old:2", "old:3", "old:7", "old:8"], found


def test_learn_reads_the_training_settings_the_metric_declares() -> None:
    from learn.midpoint.config import default_config, model_free_overrides, paper_config
    from learn.seq import default_seq_config

    finsler.register_metric(Trained)
    finsler.register_metric(Flat)
    try:
        env = "test-flat-trained"
        paper = paper_config(env)
        assert (paper.lr, paper.timesteps) == (2e-4, 123_456)
        cfg = default_config(env)
        assert (cfg.timesteps, cfg.collection_size) == (777_000, 2048)
        assert cfg.lr == default_config("test-flat-closed").lr  # the common defaults stay
        assert model_free_overrides(env) == {"path_energy_weight": 0.0, "epochs": 5}
        assert default_seq_config(env).timesteps == 123_456
        # a metric declaring nothing: the paper's Matsumoto settings, a 2e7 budget
        plain = paper_config("test-flat-closed")
        assert (plain.lr, plain.timesteps) == (3e-5, 20_000_000)
        assert default_config("test-flat-closed").timesteps == 20_000_000
        with pytest.raises(TypeError):
            Trained.training.defaults["timesteps"] = 1  # type: ignore[index]  # read-only
    finally:
        finsler.registry.unregister_metric("test-flat-trained")
        finsler.registry.unregister_metric("test-flat-closed")
    # the paper's appendix B.1 figures, now declared by the metrics themselves
    assert (paper_config("carlike").lr, paper_config("carlike").timesteps) == (1e-6, 80_000_000)
    assert (paper_config("matsumoto").lr, paper_config("matsumoto").timesteps) == (3e-5,
                                                                                   20_000_000)
    assert default_seq_config("carlike").timesteps == 80_000_000
