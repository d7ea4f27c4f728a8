"""Wall time of ``geodesics check`` (default settings) on every registered metric and on
the deliberately wrong metrics of ``tests/broken_metrics.py``, each in a fresh process
(imports and NLP builds included), with its exit status and failed properties.

    .venv/bin/python benchmarks/check_speed.py [--examples N] [--only NAME,...] [--no-broken]

Figures are for the machine it runs on; run it on an idle machine for clean numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BROKEN = ROOT / "tests" / "broken_metrics.py"


def run(name: str, examples: int, module: Path | None) -> dict:
    cmd = [sys.executable, "-m", "validation.cli", "check", "--metric", name, "--json",
           "--examples", str(examples)]
    if module is not None:
        cmd += ["--metric-module", str(module)]
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - t0
    try:
        doc = json.loads(out.stdout)
    except json.JSONDecodeError:
        return {"name": name, "wall": wall, "exit": out.returncode, "failed": ["(no JSON)"],
                "mapped": [], "error": out.stderr[-500:]}
    return {"name": name, "wall": wall, "exit": out.returncode, "failed": doc["failed"],
            "mapped": [p["name"] for p in doc["properties"] if p["status"] == "mapped"],
            "check_seconds": doc["seconds"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=100)
    ap.add_argument("--only", default="", help="comma-separated metric names")
    ap.add_argument("--no-broken", action="store_true", help="skip the broken metrics")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    import finsler

    jobs = [(n, None) for n in finsler.list_metrics()]
    if not args.no_broken:
        import broken_metrics

        jobs += [(n, BROKEN) for n in broken_metrics.EXPECTED]
    if args.only:
        keep = set(args.only.split(","))
        jobs = [j for j in jobs if j[0] in keep]
    print(f"geodesics check --examples {args.examples} (one process each, OMP_NUM_THREADS=1)")
    print(f"{'metric':20s} {'wall s':>7s} {'exit':>4s}  failed / mapped")
    for name, module in jobs:
        r = run(name, args.examples, module)
        tail = ", ".join(r["failed"]) or "-"
        if r["mapped"]:
            tail += f"  (mapped: {', '.join(r['mapped'])})"
        print(f"{name:20s} {r['wall']:7.1f} {r['exit']:4d}  {tail}", flush=True)


if __name__ == "__main__":
    main()
