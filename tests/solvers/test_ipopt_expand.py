"""IPOPT solvers are built expanded to SX (faster function evaluations): a function that
cannot be written in SX still solves, and the expanded and MX graphs give one optimum."""

from __future__ import annotations

import casadi as ca
import numpy as np

import finsler
from solvers.transcription import energy_nlp, ipopt_options


class _Square(ca.Callback):
    """x -> x**2 as a Python callback: no SX expression of it exists."""

    def __init__(self) -> None:
        ca.Callback.__init__(self)
        self.construct("square", {"enable_fd": True})

    def get_n_in(self) -> int:
        return 1

    def get_n_out(self) -> int:
        return 1

    def eval(self, arg):
        return [arg[0] ** 2]


def test_a_python_callback_solves_expanded() -> None:
    sq = _Square()
    x = ca.MX.sym("x")
    nlp = {"x": x, "f": sq(x - 3.0) + 1.0}
    opts = ipopt_options(1e-10)
    assert opts["expand"] is True
    solver = ca.nlpsol("callback", "ipopt", nlp, opts)
    out = solver(x0=0.0)
    assert abs(float(out["x"]) - 3.0) < 1e-5
    assert abs(float(out["f"]) - 1.0) < 1e-9


def test_expanded_and_mx_energy_solves_agree() -> None:
    m = finsler.get_metric("carlike")
    s, g = finsler.sample_pairs(m, 3, 20261243)[1]
    nlp = energy_nlp(m, 32)
    assert nlp.options["expand"] is True
    t = np.linspace(0.0, 1.0, 33)[:, None]
    x0 = nlp.points_to_z(s + t * (g - s))
    p = np.concatenate([s, g, [1.0]])
    expanded = nlp._call(x0, p)
    mx = ca.nlpsol("energy_mx", "ipopt", nlp.nlp, {**nlp.options, "expand": False})
    plain = mx(x0=x0, p=p, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
    assert expanded.status.converged
    assert mx.stats()["success"]
    assert abs(expanded.objective - float(plain["f"])) <= 1e-9 * abs(float(plain["f"]))
    assert np.max(np.abs(expanded.z - np.asarray(plain["x"]).ravel())) < 1e-6
