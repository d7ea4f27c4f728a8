"""The optional capabilities of a metric ("hooks"), declared in one place.

A metric must give ``F_sx(x, v)`` and a ``domain`` ([`finsler.Metric`][finsler.Metric]). Everything
below is optional. `MetricHooks` (a base of `finsler.Metric`) declares each
hook with its meaning and a default that says "not provided"; a metric provides a hook by
overriding it. The toolkit asks the metric: ``metric.provides("height_map")`` (or calls an
advice hook, whose default ``None`` means "no advice"), never ``getattr`` on a metric nor
``isinstance`` on a metric class, so a user's metric gets every behaviour the toolkit's
own metrics get by defining the same method.

=======================  ====================================================  =====================
hook                     meaning                                               used by
=======================  ====================================================  =====================
``smooth_square_sx``     ``F**2`` as a C^2 expression with slack variables,    ``solvers`` (IPOPT
                         exact at a minimiser (for an ``F`` with ``max``,      transcriptions)
                         ``abs``: the car-like metric). Default ``None``:
                         ``F_sx**2`` is used as it is.
``seed_plan``            the global seeding plan (a ``solvers.SeedPlan``) for  ``solvers`` (seeding)
                         this metric. Default ``None``: chosen from ``dim``,
                         ``smooth`` and ``convex_everywhere``.
``seed_curves``          initial curves of the metric's own geometry for the   ``solvers`` (seeding)
                         global search: ``starts, goals (K, dim), t (T,) ->
                         {family: (K, S, T, dim)}`` (e.g. car-like: cubic
                         Hermite curves along the headings).
``convex_radius``        radius of the disk about the origin where ``F(x, .)``  figures (dash-dot
                         is strongly convex (property). Default ``None``.       circle)
``height_map``           ``(N, 2) -> (N,)`` height whose slope the metric       figures (contours)
                         models, drawn as contours under 2-D paths.
``frame_positions``      forward kinematics ``(N, dim) -> (N, frames, 3)``:     figures (arm motion)
                         world positions of a robot's frames.
``landmarks``            named world points ``{name: (x, y[, z])}`` drawn with  figures (arm motion)
                         the frames (an obstacle). Default ``{}``.
``distance``             the exact distance ``(N, dim) x2 -> (N,)`` in closed   ``validation``
                         form (a reference for tests and the propositions).     (propositions)
``geodesic``             the exact minimising geodesic at arc-length fractions
                         ``t``: ``(N, dim) x2, (T,) -> (N, T, dim)``.
``conformal_factor_sx``  the factor ``f(x)`` of a conformal metric             ``solvers`` (certify
                         ``F(x, v) = f(x) |v|``, an SX expression of ``x``.    in n-D)
=======================  ====================================================  =====================

``Metric.hooks()`` lists the hooks a metric provides (also in ``Metric.info()`` and
``geodesics metrics``).
"""

from __future__ import annotations

from typing import Any, ClassVar

from finsler.errors import InputError

__all__ = ["HOOKS", "MetricHooks"]

#: Every optional hook of a metric, in the order of the table above.
HOOKS: tuple[str, ...] = ("smooth_square_sx", "seed_plan", "seed_curves", "convex_radius",
                          "height_map", "frame_positions", "landmarks", "distance",
                          "geodesic", "conformal_factor_sx")


class MetricHooks:
    """The optional hooks of `finsler.Metric` (see the module docstring): each one's
    default here means "not provided"."""

    HOOKS: ClassVar[tuple[str, ...]] = HOOKS

    def provides(self, hook: str) -> bool:
        """True if this metric provides the optional ``hook`` (one of `HOOKS`), i.e.
        its class overrides the default declared here."""
        if hook not in HOOKS:
            raise InputError(f"unknown metric hook {hook!r}; the hooks are: {', '.join(HOOKS)}")
        return getattr(type(self), hook) is not getattr(MetricHooks, hook)

    def hooks(self) -> tuple[str, ...]:
        """The optional hooks this metric provides, in the order of `HOOKS`."""
        return tuple(h for h in HOOKS if self.provides(h))

    def _missing(self, hook: str) -> InputError:
        name = getattr(self, "name", type(self).__name__)
        return InputError(f"metric {name!r} does not provide the hook {hook!r} (see "
                          "finsler.hooks; ask metric.provides(hook) first)")

    # -- advice for the exact solvers -----------------------------------------------------
    def smooth_square_sx(self, x: Any, v: Any, tag: str = "") -> dict[str, Any] | None:
        """``F(x, v)**2`` as a smooth (C^2) CasADi expression of ``(x, v, w)`` with slack
        symbols ``w``, exact at any minimiser of an objective increasing in ``F**2``; for a
        metric whose ``F`` is not C^2 (``max``, ``abs``). ``tag`` makes the slack names
        unique per segment.

        Returns ``None`` (the default: ``F_sx(x, v)**2`` is smooth enough) or a dict:
        ``f2`` (SX scalar), ``w`` (slack symbols ``(k, 1)``) with bounds ``lbw`` / ``ubw``
        (lists of k floats), ``w_value`` (the exact slacks as an expression of ``(x, v)``,
        for initial points), constraints ``g`` ``(m, 1)`` with bounds ``lbg`` / ``ubg``.
        """
        return None

    def seed_plan(self) -> Any:
        """The global seeding plan of the exact solver for this metric (a
        ``solvers.SeedPlan``), or ``None`` (the default: the solver chooses one from
        ``dim``, ``smooth`` and ``convex_everywhere``)."""
        return None

    def seed_curves(self, starts: Any, goals: Any, t: Any) -> dict[str, Any]:
        """Initial curves that know this metric's geometry, for the global search of the
        exact solvers (beside the generic seeds of ``solvers.SeedPlan``): for pairs
        ``starts``, ``goals`` ``(K, dim)`` and curve parameters ``t`` ``(T,)`` (from 0 to
        1), a dict ``{family: (K, S, T, dim)}``: ``S`` curves per pair of each named
        family, from ``starts[k]`` at ``t = 0`` to ``goals[k]`` at ``t = 1``. The solver
        projects them into the domain and pins their ends; results report how each
        family fared (``GeodesicResult.seed_families``). Family names are short words
        (letters, digits, ``-``). Not provided by default."""
        raise self._missing("seed_curves")

    # -- drawing ----------------------------------------------------------------------------
    @property
    def convex_radius(self) -> float | None:
        """Radius of the disk about the origin inside which ``F(x, .)`` is strongly convex
        (drawn on 2-D path figures), or ``None`` (the default: no such disk is known)."""
        return None

    def height_map(self, points: Any) -> Any:
        """The height ``h(p)`` of 2-D points ``(N, 2) -> (N,)`` whose slope the metric
        models (drawn as contours under 2-D paths). Not provided by default."""
        raise self._missing("height_map")

    def frame_positions(self, q: Any) -> Any:
        """Forward kinematics: world positions of the frames of a robot in configuration
        ``q`` ``(N, dim) -> (N, frames, 3)`` (drawn as the arm's motion). Not provided by
        default."""
        raise self._missing("frame_positions")

    def landmarks(self) -> dict[str, tuple[float, ...]]:
        """Named points of the world frame of `frame_positions`
        ``{name: (x, y[, z])}``, e.g. an obstacle, drawn with the frames. Default: none."""
        return {}

    # -- closed-form references -----------------------------------------------------------
    def distance(self, x: Any, y: Any) -> Any:
        """The exact distance ``d(x, y)`` in closed form, ``(N, dim)`` x2 -> ``(N,)`` (a
        reference for tests). Not provided by default: compute distances with
        ``solvers.distance``."""
        raise self._missing("distance")

    def geodesic(self, x: Any, y: Any, t: Any) -> Any:
        """Points of the exact minimising geodesic from ``x`` to ``y`` at arc-length
        fractions ``t`` ``(T,)``: ``(N, dim)`` x2 -> ``(N, T, dim)``. Not provided by
        default."""
        raise self._missing("geodesic")

    # -- structure ----------------------------------------------------------------------
    def conformal_factor_sx(self, x: Any) -> Any:
        """The factor ``f(x) > 0`` of a conformal metric, ``F(x, v) = f(x) |v|`` with
        ``|v|`` the Euclidean norm, as a CasADi SX expression of ``x`` (``(dim, 1)`` SX ->
        ``(1, 1)`` SX). A metric provides it only if ``F`` has exactly this form: the n-D
        certificate (``solvers.certificates.conformal.certificate``) proves its lower bound from
        enclosures of this factor alone. Not provided by default."""
        raise self._missing("conformal_factor_sx")
