"""The README's Python examples run as written and do what they say."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

import finsler

README = Path(__file__).resolve().parents[2] / "README.md"


def _python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_examples_run_and_define_a_working_metric(tmp_path, monkeypatch) -> None:
    blocks = _python_blocks()
    assert len(blocks) >= 2
    for block in blocks:  # a block headed "# NAME.py" is a file the README says to save
        name = re.match(r"# ([\w.-]+\.py)\b", block)
        if name:
            (tmp_path / name.group(1)).write_text(block)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(__import__("sys").modules, "wavy", raising=False)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(README), "exec"), namespace)
    # the Python API block: shapes and values it claims
    assert namespace["paths"].shape == (100, 65, 2)
    pm = finsler.get_metric("poincare")
    exact = pm.distance(np.array([[0.1, 0.2]]), np.array([[-0.3, 0.4]]))[0]
    d = namespace["d"]
    assert abs(d.distance - exact) <= 1e-8 * exact
    assert np.allclose(namespace["res"].points[[0, -1]], namespace["pairs"][0])
    try:
        m = finsler.get_metric("wavy", a=0.2)
        x = np.array([[0.1, 0.2], [0.0, 0.0]])
        y = np.array([[0.3, -0.1], [0.5, 0.0]])
        ref = (1 + 0.2 * np.sin(3 * x[:, 0]) ** 2) * np.linalg.norm(y - x, axis=1)
        assert np.allclose(m.cost(x, y), ref, rtol=1e-14)
        assert np.all(m.convexity(x) > 0)
    finally:
        finsler.registry._REGISTRY.pop("wavy", None)


def test_readme_names_the_two_commands() -> None:
    text = README.read_text()
    assert 'pip install -e ".[dev]"' in text
    assert ".venv/bin/python -m pytest -n 2" in text
    ci = (README.parent / ".ci" / "run").read_text()
    assert '.venv/bin/pip install -e ".[dev]"' in ci
    assert ".venv/bin/python -m pytest -n 2" in ci
