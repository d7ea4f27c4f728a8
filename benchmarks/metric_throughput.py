"""Throughput of the local cost C (eq. 4): lowered torch / lowered numpy / CasADi map.

Prints evaluations per second on one million random pairs (Panda: 100k) for each
backend and the ratios lowered/CasADi measured in the same run, plus a hand-written
vectorised numpy Matsumoto formula for comparison.

    python benchmarks/metric_throughput.py [--n 1000000] [--repeat 3] [--threads 2]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import torch

import finsler


def best_time(fn: Callable[[], object], repeat: int) -> float:
    fn()  # warm up (compiles / caches)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def matsumoto_by_hand(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    v = y - x
    beta = -2.0 * (x[:, 0] * v[:, 0] + x[:, 1] * v[:, 1])
    a2 = v[:, 0] ** 2 + v[:, 1] ** 2 + beta**2
    return a2 / (np.sqrt(a2) - beta)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="pairs (Panda uses n / 10)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} thread(s); best of {args.repeat} runs")
    header = (
        f"{'metric':<11} {'pairs':>8} {'torch /s':>12} {'numpy /s':>12} {'casadi map /s':>14}"
        f" {'torch/casadi':>13} {'numpy/casadi':>13}"
    )
    print(header)
    print("-" * len(header))
    for name in ("matsumoto", "carlike", "panda-pole"):
        m = finsler.get_metric(name)
        n = args.n // 10 if name == "panda-pole" else args.n
        rng = np.random.default_rng(0)
        x, y = m.domain.sample(n, rng), m.domain.sample(n, rng)
        xt, yt = torch.from_numpy(x), torch.from_numpy(y)
        mapped = m.casadi_cost.map(n, "serial")
        xT, yT = np.ascontiguousarray(x.T), np.ascontiguousarray(y.T)
        ref = np.asarray(mapped(xT, yT)).ravel()
        assert np.allclose(m.cost(x, y), ref, rtol=1e-12)
        assert np.allclose(m.cost(xt, yt).numpy(), ref, rtol=1e-12)
        t_torch = best_time(lambda: m.cost(xt, yt), args.repeat)  # noqa: B023
        t_numpy = best_time(lambda: m.cost(x, y), args.repeat)  # noqa: B023
        t_casadi = best_time(lambda: mapped(xT, yT), args.repeat)  # noqa: B023
        print(
            f"{name:<11} {n:>8} {n / t_torch:>12.3e} {n / t_numpy:>12.3e} {n / t_casadi:>14.3e}"
            f" {t_casadi / t_torch:>12.1f}x {t_casadi / t_numpy:>12.1f}x"
        )
        if name == "matsumoto":
            assert np.allclose(matsumoto_by_hand(x, y), ref, rtol=1e-12)
            t_hand = best_time(lambda: matsumoto_by_hand(x, y), args.repeat)  # noqa: B023
            print(
                f"{'':<11} hand-written numpy formula: {n / t_hand:.3e} /s; lowered numpy takes "
                f"{t_numpy / t_hand:.2f}x its time, lowered torch {t_torch / t_hand:.2f}x"
            )


if __name__ == "__main__":
    main()
