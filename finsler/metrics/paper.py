"""The paper's environments: Matsumoto (a slope), the car-like metric and the Panda pole
metric, each with its task and training settings.

Each metric is written exactly once, as the CasADi SX expression returned by
``F_sx``; every numeric evaluator is derived from it (`finsler.metrics.base`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler.domains import Box, Disk, Domain, JointBox, Product, _as_batch
from finsler.errors import InputError
from finsler.metrics.base import Metric, Task, TrainingSettings

__all__ = ["MATSUMOTO_CONVEX_RADIUS", "CarLike", "Matsumoto", "PandaPole"]

#: Radius below which the paper's Matsumoto metric (h = -|p|^2) is strongly convex:
#: ||beta||_alpha < 1/2  <=>  |grad h| < 1/sqrt(3)  <=>  |p| < 1/(2 sqrt 3).
MATSUMOTO_CONVEX_RADIUS = 1.0 / (2.0 * math.sqrt(3.0))


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"parameter {name} must be positive and finite, got {value!r}")


@dataclass(frozen=True)
class Matsumoto(Metric):
    """Matsumoto slope metric, eqs. (20)-(21): ``F = alpha**2 / (alpha - beta)`` with
    ``beta = <grad h(p), v>``, ``alpha = sqrt(|v|**2 + beta**2)`` and the height
    ``h(p) = -height * |p|**2`` (a mountain at the centre) on the unit disk.

    Not Finsler everywhere: ``F(p, .)`` is strongly convex only where
    ``||beta||_alpha < 1/2``, i.e. ``|grad h| < 1/sqrt(3)``; for the default
    ``height = 1`` that is ``|p| < 1/(2 sqrt 3) ~ 0.2887`` (about 8% of the disk).
    """

    height: float = 1.0
    radius: float = 1.0

    name: ClassVar[str] = "matsumoto"
    task: ClassVar[Task] = Task(depth=6, eps=0.1)
    # The paper's settings (appendix B.1) and the toolkit's measured training defaults,
    # read by learn (learn.config.default_config / paper_config, learn.seq); the
    # measurements behind each default: docs/guides/training-defaults.md.
    training: ClassVar[TrainingSettings] = TrainingSettings(
        paper_lr=3e-5, paper_timesteps=20_000_000,
        defaults=dict(timesteps=100_000_000, hidden=(128, 128, 128), critic_hidden=(64, 64),
                      epochs=3, fused_adam=True, actor_relative=True,
                      critic_transform="relative"),
        # model-free (Algorithm 1 alone, values of C only): 3 epochs, the fastest to 95 %
        # (learn.config.model_free_overrides)
        model_free=dict(epochs=3),
    )
    reversible: ClassVar[bool] = False
    convex_everywhere: ClassVar[bool] = False
    convexity_note: ClassVar[str] = (
        "NOT Finsler everywhere: F(x,.) convex only for |p| < 1/(2*sqrt(3)*height) "
        "(~0.2887 at height 1)"
    )

    def __post_init__(self) -> None:
        _positive("height", self.height)
        _positive("radius", self.radius)

    @property
    def domain(self) -> Domain:
        return Disk(radius=self.radius)

    @property
    def convex_radius(self) -> float:
        """Hook: analytic radius of the region where ``F(p, .)`` is strongly convex."""
        return MATSUMOTO_CONVEX_RADIUS / self.height

    def height_map(self, points: Any) -> np.ndarray:
        """Hook: the height ``h(p) = -height |p|**2`` of eq. (21), ``(N, 2) -> (N,)``
        (``F_sx`` uses its gradient ``-2 height p``)."""
        p = np.asarray(points, dtype=np.float64)
        return -self.height * np.sum(p * p, axis=-1)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        grad_h = -2.0 * self.height * x  # the gradient of height_map's h
        beta = ca.dot(grad_h, v)
        alpha = ca.sqrt(ca.dot(v, v) + beta * beta)
        return alpha * alpha / (alpha - beta)


@dataclass(frozen=True)
class CarLike(Metric):
    """Unidirectional car-like metric, eqs. (22)-(24), on (unit disk) x [-pi, pi]:
    ``F = sqrt(vx**2 + vy**2 + c_p (h**2 + xi**2))`` with the sideways motion
    ``h = -vx sin(th) + vy cos(th)`` and ``xi = max(r_min |v_th| - vx cos(th) - vy sin(th), 0)``.

    A C^0-Finsler structure (appendix D): ``F(x, .)`` is convex but not smooth.
    theta is a plain coordinate (not identified at +-pi).
    """

    c_p: float = 100.0
    r_min: float = 0.5
    radius: float = 1.0

    name: ClassVar[str] = "carlike"
    task: ClassVar[Task] = Task(depth=8, eps=0.1)
    # The paper's settings (appendix B.1) and the toolkit's measured training defaults,
    # read by learn (learn.config.default_config / paper_config, learn.seq); the
    # measurements behind each default: docs/guides/training-defaults.md.
    training: ClassVar[TrainingSettings] = TrainingSettings(
        paper_lr=1e-6, paper_timesteps=80_000_000,
        defaults=dict(timesteps=400_000_000, hidden=(128, 128), epochs=1, fused_adam=True,
                      path_energy_weight=1.0, path_energy_pairs=16, path_energy_power=4.0,
                      actor_relative=True),
        # model-free (Algorithm 1 alone): 2 epochs
        model_free=dict(epochs=2),
    )
    reversible: ClassVar[bool] = False
    smooth: ClassVar[bool] = False
    convexity_note: ClassVar[str] = "C^0-Finsler: convex but not smooth (max, abs)"

    def __post_init__(self) -> None:
        _positive("c_p", self.c_p)
        _positive("r_min", self.r_min)
        _positive("radius", self.radius)

    @property
    def domain(self) -> Domain:
        return Product(
            (Disk(radius=self.radius), Box((-math.pi,), (math.pi,), names=("theta",)))
        )

    def _square_sx(self, x: ca.SX, v: ca.SX, xi: ca.SX | None = None
                   ) -> tuple[ca.SX, ca.SX, ca.SX]:
        """The formula, written once for ``F_sx`` and the smooth hook: returns
        ``(vx**2 + vy**2 + c_p (h**2 + xi**2), u, excess)`` with the forward speed
        ``u = vx cos(th) + vy sin(th)``, the excess turning rate
        ``excess = max(r_min |v_th| - u, 0)``, and ``xi = excess`` unless given (then the
        first entry is ``F**2`` exactly when ``xi == excess``)."""
        th = x[2]
        c, s = ca.cos(th), ca.sin(th)
        h = -v[0] * s + v[1] * c
        u = v[0] * c + v[1] * s
        excess = ca.fmax(self.r_min * ca.fabs(v[2]) - v[0] * c - v[1] * s, 0.0)
        w = excess if xi is None else xi
        return v[0] * v[0] + v[1] * v[1] + self.c_p * (h * h + w * w), u, excess

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.sqrt(self._square_sx(x, v)[0])

    def smooth_square_sx(self, x: ca.SX, v: ca.SX, tag: str = "") -> dict[str, Any]:
        """Hook (`finsler.hooks`) for optimisers that need C^2 functions (solvers'
        transcriptions): ``F**2`` as a smooth expression of ``(x, v, xi)`` with one slack
        ``xi``, exact at any minimiser of an objective increasing in ``F**2``.

        ``max(r_min |v_th| - u, 0)`` becomes ``xi >= 0``, ``xi >= r_min v_th - u``,
        ``xi >= -r_min v_th - u``: the objective increases with ``xi**2``, so at a minimiser
        ``xi`` equals the max. Returns a dict: ``f2`` (SX scalar), ``w`` (slack symbols
        ``(1, 1)``) with bounds ``lbw``/``ubw``, ``w_value`` (the exact slack as an
        expression of ``(x, v)``, for initial points), constraints ``g`` ``(2, 1)`` with
        bounds ``lbg``/``ubg``.
        """
        xi = ca.SX.sym(f"xi{tag}")
        f2, u, excess = self._square_sx(x, v, xi)
        g = ca.vertcat(xi - (self.r_min * v[2] - u), xi - (-self.r_min * v[2] - u))
        return {"f2": f2, "w": xi, "w_value": excess, "lbw": [0.0],
                "ubw": [ca.inf], "g": g, "lbg": [0.0, 0.0], "ubg": [ca.inf, ca.inf]}

    #: Tangent lengths (times ``radius``) of the Hermite seed curves, and how their
    #: heading is laid (see `seed_curves`): the set that found every basin of the
    #: tuning pairs at the least solve time (docs/guides/training-defaults.md).
    SEED_TANGENTS: ClassVar[tuple[float, ...]] = (0.25, 0.5, 1.0, 2.0, 6.0)
    SEED_HEADINGS: ClassVar[tuple[str, ...]] = ("track", "shift", "linear")

    def seed_curves(self, starts: Any, goals: Any, t: Any) -> dict[str, np.ndarray]:
        """Hook (`finsler.hooks`): cubic Hermite curves in the plane whose end
        tangents follow the start and goal headings (forward motion), one per tangent
        length of ``SEED_TANGENTS``, for each way of laying the heading along them
        (family ``hermite-<way>``): ``track`` follows the curve's tangent direction,
        the winding left at the goal spread evenly; ``shift`` follows it and drops the
        winding at the middle (the solve then chooses which way to turn); ``linear``
        interpolates the end headings; ``raw`` wraps the tangent direction into
        ``[-pi, pi]``; ``clip`` clips it there. The heading is a plain coordinate here
        (not identified at +-pi), so these are distinct ways of turning."""
        s = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
        g = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
        tt = np.asarray(t, dtype=np.float64).reshape(-1)
        tc = tt[None, None, :, None]  # (1, 1, T, 1)
        lengths = self.radius * np.asarray(self.SEED_TANGENTS)[None, :, None, None]
        d0 = np.stack([np.cos(s[:, 2]), np.sin(s[:, 2])], -1)[:, None, None]  # (K,1,1,2)
        d1 = np.stack([np.cos(g[:, 2]), np.sin(g[:, 2])], -1)[:, None, None]
        p0, p1 = s[:, None, None, :2], g[:, None, None, :2]
        h00, h10 = 2 * tc**3 - 3 * tc**2 + 1, tc**3 - 2 * tc**2 + tc
        h01, h11 = -2 * tc**3 + 3 * tc**2, tc**3 - tc**2
        p = h00 * p0 + h10 * lengths * d0 + h01 * p1 + h11 * lengths * d1  # (K, S, T, 2)
        # the tangent's direction (the derivative in closed form: exact at the ends)
        dp = ((6 * tc**2 - 6 * tc) * p0 + (3 * tc**2 - 4 * tc + 1) * lengths * d0
              + (-6 * tc**2 + 6 * tc) * p1 + (3 * tc**2 - 2 * tc) * lengths * d1)
        raw = np.arctan2(dp[..., 1], dp[..., 0])  # (K, S, T)
        track = np.unwrap(raw, axis=-1)
        track = track - track[..., :1] + s[:, None, None, 2]
        th0, th1 = s[:, None, None, 2], g[:, None, None, 2]
        tp = tt[None, None, :]
        ways = {
            "track": track + tp * (th1 - track[..., -1:]),
            "shift": track - 2 * np.pi * np.round((track[..., -1:] - th1) / (2 * np.pi))
            * (tp > 0.5),
            "linear": np.broadcast_to(th0 + tp * (th1 - th0), track.shape),
            "raw": raw,
            "clip": np.clip(track, -np.pi, np.pi),
        }
        out = {}
        for way in self.SEED_HEADINGS:
            c = np.concatenate([p, ways[way][..., None]], -1)
            c = np.asarray(self.domain.project(c.reshape(-1, 3))).reshape(c.shape)
            c[:, :, 0], c[:, :, -1] = s[:, None], g[:, None]
            out[f"hermite-{way}"] = c
        return out


@dataclass(frozen=True)
class PandaPole(Metric):
    """Franka Panda joint space with a pole obstacle, eq. (60):
    ``F(q, v) = (1 + sum_i ((p_i(q)_x - o_x)**2 + (p_i(q)_y - o_y)**2)**(-1/2)) |v|`` with
    ``p_i`` the positions of the frames panda_link0..panda_link8, panda_hand (Pinocchio's
    Panda model from example-robot-data) and the joint-limit box as domain.
    """

    pole_x: float = 0.4
    pole_y: float = 0.0

    name: ClassVar[str] = "panda-pole"
    # The paper's settings (appendix B.1) and the toolkit's measured training defaults,
    # read by learn (learn.config.default_config / paper_config, learn.seq); the
    # measurements behind each default: docs/guides/training-defaults.md.
    training: ClassVar[TrainingSettings] = TrainingSettings(
        paper_lr=1e-6, paper_timesteps=20_000_000,
        defaults=dict(timesteps=20_000_000, hidden=(256, 256, 256), critic_hidden=(128, 128),
                      symmetric_critic=True, eval_every=25, actor_loss_power=8.0,
                      select_eps=10.0, polish_steps=3000),
        pg_cycles=(1077, 1077),
    )
    task: ClassVar[Task] = Task(depth=5, eps=20.0)
    reversible: ClassVar[bool] = True
    convexity_note: ClassVar[str] = "Riemannian (conformal): Finsler everywhere"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pole_x) and math.isfinite(self.pole_y)):
            raise InputError("pole position must be finite")

    @property
    def domain(self) -> Domain:
        from finsler.metrics import panda

        return JointBox(
            tuple(panda.JOINT_LIMITS_LOW.tolist()),
            tuple(panda.JOINT_LIMITS_HIGH.tolist()),
            names=tuple(f"q{i + 1}" for i in range(7)),
        )

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        from finsler.metrics import panda

        return panda.pole_metric_sx(x, v, pole=(self.pole_x, self.pole_y))

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        """Hook: ``F(q, v) = f(q) |v|`` with ``f`` eq. (60)'s weight ``1 + sum_i
        rho_i**(-1/2)``, ``rho_i`` the squared horizontal distances of the frames to the
        pole. Written with the power ``-1/2`` rather than ``1 / sqrt``: its interval
        enclosure on boxes where a frame may reach the pole's axis is the half-line
        ``[rho_max**(-1/2), inf]``, not the whole line (tests check it equals ``F_sx``)."""
        from finsler.metrics import panda

        p = panda.frame_positions_sx(x)
        squared = (p[:, 0] - self.pole_x) ** 2 + (p[:, 1] - self.pole_y) ** 2
        return 1 + ca.sum1(squared ** -0.5)

    def landmarks(self) -> dict[str, tuple[float, ...]]:
        """Hook: the pole's position in the world frame (x, y)."""
        return {"pole": (float(self.pole_x), float(self.pole_y))}

    def frame_positions(self, q: Any) -> Any:
        """Hook: world positions of the ten frames, ``(N, 7)`` -> ``(N, 10, 3)`` (lowered CasADi
        forward kinematics; numpy or torch)."""
        from finsler.metrics import panda

        qb = _as_batch(q, 7, "q")
        (p,) = panda.lowered_frame_positions()(qb)
        p = p.reshape(-1, 3, 10)  # CasADi stores the (10, 3) matrix column-major
        return p.transpose(1, 2) if hasattr(p, "detach") else p.transpose(0, 2, 1)
