"""The durable store of every method's per-pair answers behind ``ground_truth.py``'s best known.

A ground-truth run compares a default with the best known of its pairs. A multistart alone
is not the truth (on car-like the batched interior point found lower basins than a wide
IPOPT multistart on 11 of 100 pairs), so every method's energies a run computes are kept
here, next to the multistart cache: one small JSON file per pair set
``ground_truth_cache/<metric>-answers-<key>.json``, ``<key>`` a digest of the metric's
parameters, the pairs' seed, K and N (the same pairs whatever the plan).

In it, one entry per *label*: the method and a digest of its seed plan
(:func:`plan_label`), so that a changed plan is stored apart and a run never takes another
plan's answers for those of the default it measures. Each entry holds the energy and the
convergence flag of every pair (``null``: not computed, e.g. a ``--first`` run), the commit
and the date. The best known of a run is the lowest of its default, the multistart and
every *other* label's converged energies: stored answers only lower the best known (a
stale entry is still a valid path's energy), and the measured default is always solved
afresh, never read from here. A rerun of a label that ends higher than its stored answer on
some pair (or fails to converge there) keeps the earlier entry apart, as
``<label>@<commit> <date>``, so that a best known never rises.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import subprocess
import time
from pathlib import Path

import numpy as np
from results_file import RESULTS

import finsler
from finsler.spec import MetricSpec
from solvers import SeedPlan

STORE = RESULTS / "ground_truth_cache"


def _digest(obj: object) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:12]


def store_path(metric: finsler.Metric, seed: int, k: int, n: int,
               root: Path | None = None) -> Path:
    """The store file of the pairs ``sample_pairs(metric, k, seed)`` at ``n`` segments."""
    key = {"spec": MetricSpec.of(metric).to_dict(), "seed": seed, "K": k, "N": n}
    return (root or STORE) / f"{metric.name}-answers-{_digest(key)}.json"


def plan_label(metric: finsler.Metric, method: str) -> str:
    """``<method>-default-<digest>``: the solver ``method`` and a digest of every field of
    its default plan ``SeedPlan.default(metric, method)`` (a plan change, a new label)."""
    plan = SeedPlan.default(metric, method)
    return f"{method}-default-{_digest(dataclasses.asdict(plan))}"


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, cwd=Path(__file__).parent, timeout=10, check=False)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def load(path: Path) -> dict:
    """The store at ``path`` (an empty one if there is none)."""
    if not path.exists():
        return {"answers": {}}
    return json.loads(path.read_text())


def record(path: Path, label: str, energy, converged, meta: dict, first: int = 0,
           source: str = "ground_truth.py", commit: str | None = None) -> None:
    """Keep ``energy`` / ``converged`` of pairs ``first .. first + len - 1`` (of the
    ``meta["K"]``) under ``label``, written at once (other pairs of the label kept);
    ``commit``: of the code that computed them (default: the work tree's HEAD)."""
    k = int(meta["K"])
    store = load(path)
    store.update({f: meta[f] for f in ("metric", "seed", "K", "N")})
    old = store["answers"].get(label, {"energy": [None] * k, "converged": [None] * k})
    e, c = list(old["energy"]), list(old["converged"])
    lost = False  # would a lower converged answer of the label be overwritten?
    for i, (ei, ci) in enumerate(zip(energy, converged, strict=True)):
        ei = float(ei)
        prev, prev_ok = e[first + i], c[first + i]
        if prev is not None and prev_ok and not (ci and math.isfinite(ei)
                                                 and ei <= prev * (1 + 1e-12)):
            lost = True
        e[first + i] = ei if math.isfinite(ei) else None
        c[first + i] = bool(ci)
    if lost:
        # a rerun of the same plan (a rounding-level change of the code, say) ended higher
        # on some pair: the earlier answers stay, under their own label, so that the best
        # known never rises
        store["answers"][f"{label}@{old.get('commit', 'unknown')} {old.get('date', '')}"
                         .rstrip()] = old
    store["answers"][label] = {"energy": e, "converged": c, "commit": commit or _commit(),
                               "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                               "source": source}
    path.parent.mkdir(parents=True, exist_ok=True)
    finsler.atomic_write_text(path, json.dumps(store, indent=1), "answer store")


def stored(store: dict, k: int, exclude: str | None = None) -> dict[str, np.ndarray]:
    """Per label but ``exclude``: the energies of the first ``k`` pairs, ``inf`` where a pair
    was not computed or did not converge (only converged answers lower a best known)."""
    out = {}
    for label, a in store.get("answers", {}).items():
        if label == exclude:
            continue
        e = np.array([x if (x is not None and c) else np.inf
                      for x, c in zip(a["energy"][:k], a["converged"][:k], strict=True)],
                     dtype=np.float64)
        out[label] = e
    return out
