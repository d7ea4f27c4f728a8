"""The actor in pieces of ``learn.midpoint.networks.PREDICT_ROWS`` rows against one call: CPU and
wall time of the shipped policies' predictions, plain generation and the route search,
both ways in one run, with a check that the paths agree bit for bit.

Run:  python benchmarks/predict_rows.py [--envs matsumoto,carlike,panda-pole]
      [--predictions 100000] [--generate 10000] [--search 50] [--threads 1]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from functools import partial

import torch

import finsler
import learn
from learn.midpoint.networks import PREDICT_ROWS, predictor
from learn.midpoint.search import search_paths
from learn.tree import build_tree

Predict = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def timed(fn: Callable[[], object], repeats: int) -> tuple[float, float, object]:
    """Best-of-``repeats`` (wall, CPU) seconds of ``fn()`` and its last result."""
    fn()  # warm-up
    wall = cpu = float("inf")
    out = None
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        wall, cpu = min(wall, time.perf_counter() - t), min(cpu, time.process_time() - c)
    return wall, cpu, out


def jobs(policy: learn.Policy, args: argparse.Namespace
         ) -> list[tuple[str, Callable[[Predict], torch.Tensor], int, int]]:
    """(label, job(predict) -> tensor, repeats, paths or predictions) of one policy."""
    m, depth = policy.metric, policy.depth
    n = max(args.predictions, args.generate, args.search)
    pairs = torch.as_tensor(finsler.sample_pairs(m, n, seed=11))
    s, g = pairs[:, 0], pairs[:, 1]
    k1, k2, k3 = args.predictions, args.generate, args.search

    def predictions(p: Predict) -> torch.Tensor:
        return p(s[:k1], g[:k1])

    def generate(p: Predict) -> torch.Tensor:
        return build_tree(s[:k2], g[:k2], depth, p)

    def search(p: Predict) -> torch.Tensor:
        return torch.as_tensor(search_paths(m, p, s[:k3], g[:k3], depth, policy.eps).paths)

    return [(f"{k1} predictions", predictions, 3, k1),
            (f"generate {k2} paths", generate, 3, k2),
            (f"search {k3} paths", search, 2, k3)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", default="matsumoto,carlike,panda-pole")
    ap.add_argument("--predictions", type=int, default=100_000)
    ap.add_argument("--generate", type=int, default=10_000)
    ap.add_argument("--search", type=int, default=50)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"rows per piece: {PREDICT_ROWS}; torch {torch.__version__}, "
          f"{torch.get_num_threads()} thread(s); best of 3 (search: of 2)")
    print("env          what                      one call wall / CPU   pieces wall / CPU"
          "   speed-up (CPU)  same bits")
    for env in args.envs.split(","):
        policy = learn.load_policy(env)
        one = predictor(policy.actor, policy.metric, rows=None)
        pieces = predictor(policy.actor, policy.metric)
        for what, job, repeats, count in jobs(policy, args):
            with torch.no_grad():
                w1, c1, o1 = timed(partial(job, one), repeats)
                w2, c2, o2 = timed(partial(job, pieces), repeats)
            same = bool(torch.equal(o1, o2))
            unit = 1e3 / count
            print(f"{env:12s} {what:25s} {w1 * unit:8.4f} / {c1 * unit:8.4f}  "
                  f"{w2 * unit:8.4f} / {c2 * unit:8.4f}   {c1 / c2:6.2f}x        {same}")
    print("times in ms per prediction or per path")


if __name__ == "__main__":
    main()
