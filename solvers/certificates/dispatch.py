"""The one entry of the certificates: [`certify`][solvers.certify] picks the certificate by
what the metric provides, and `certify_settings` builds that certificate's settings from a
preset and the few overrides a caller (the ``geodesics certify`` command) names.

Which certificate (`certificate_kind`):

* ``"conformal"``: a metric of more than 3 dimensions with the hook
  ``conformal_factor_sx`` (``F(q, v) = f(q) |v|``): the best of the conformal bounds
  (`solvers.certificates.conformal.split.certify_conformal_best`), settings
  `ConformalSpec`;
* ``"plane"``: any other 2-D metric: a P2 potential on a refined mesh
  (`solvers.certificates.plane.certificate.certify_plane`), settings `MeshSpec`;
* ``"nd"``: any other dimension: a potential verified cell by cell
  (`solvers.certificates.nd.certificate.certify_nd`), settings `NDSpec`.

Each returns a [`Certificate`][solvers.result.Certificate] (the common base of the three
result types), so ``certify``'s declared type is the one every caller can rely on.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, Literal, TypeAlias

from finsler.errors import InputError
from finsler.metrics.base import Metric
from solvers.certificates.conformal.certificate import ConformalSpec
from solvers.certificates.nd.certificate import NDSpec
from solvers.certificates.plane.certificate import MeshSpec
from solvers.inputs import as_metric, domain_scale
from solvers.result import Certificate

__all__ = ["CertifySettings", "certificate_kind", "certify", "certify_settings"]

#: The settings of one certificate: which type goes with which certificate is in the
#: module docstring (`certificate_kind`).
CertifySettings: TypeAlias = MeshSpec | NDSpec | ConformalSpec

_SETTINGS: dict[str, type] = {"plane": MeshSpec, "nd": NDSpec, "conformal": ConformalSpec}


def certificate_kind(metric: Metric | str) -> Literal["plane", "nd", "conformal"]:
    """The certificate `certify` runs for ``metric``: ``"conformal"``, ``"plane"`` or
    ``"nd"`` (the rule is in the module docstring)."""
    return _kind(as_metric(metric))


def _kind(m: Metric) -> Literal["plane", "nd", "conformal"]:
    if m.dim > 3 and m.provides("conformal_factor_sx"):
        return "conformal"
    return "plane" if m.dim == 2 else "nd"


def certify_settings(metric: Metric | str, preset: str = "default", *,
                     h: float | None = None, directions: int | None = None,
                     target_gap: float | None = None, max_boxes: int | None = None,
                     names: Mapping[str, str] | None = None) -> CertifySettings:
    """The settings of ``metric``'s certificate: ``preset`` (``"coarse"``, ``"default"``,
    ``"fine"``; ``"p2"`` in 3-D and up) with the overrides given. ``h``: spacing of the
    first mesh along the path (mesh certificates); ``directions``: sampled directions per
    triangle (2-D); ``target_gap``: refine until the relative gap is at most this;
    ``max_boxes``: work budget in box enclosures (conformal). An override the metric's
    certificate has no use for is ignored. Raises `InputError` for an unknown preset or an
    override out of range; ``names``: how its messages name the overrides (the command
    line names ``--target-gap``, ...; ``"preset"`` names the preset)."""
    return _settings(as_metric(metric), preset, h, directions, target_gap, max_boxes, names)


def _settings(m: Metric, preset: str, h: float | None, directions: int | None,
              target_gap: float | None, max_boxes: int | None,
              names: Mapping[str, str] | None = None) -> CertifySettings:
    """`certify_settings` of a metric object."""
    name = ({k: k for k in ("h", "directions", "target_gap", "max_boxes")}
            | {"preset": "mesh preset"} | dict(names or {}))
    kind = _kind(m)
    if preset == "p2" and kind == "plane":
        raise InputError(f"{name['preset']} p2 (a piecewise-quadratic potential) is for metrics of "
                         f"3 and more dimensions; {m.name} is 2-D: choose coarse, default or "
                         "fine")
    spec = _SETTINGS[kind].preset(preset)
    changes: dict[str, Any] = {}
    if target_gap is not None:
        if not (isinstance(target_gap, (int, float)) and math.isfinite(target_gap)
                and 0 < target_gap < 1):
            raise InputError(f"{name['target_gap']} must be in (0, 1), got {target_gap!r}")
        changes["target_gap"] = target_gap
    if kind == "conformal":
        if max_boxes is not None:
            changes["max_boxes"] = max_boxes
        return dataclasses.replace(spec, **changes)
    if h is not None:
        scale = domain_scale(m)
        if not (isinstance(h, (int, float)) and math.isfinite(h) and 0 < h <= scale):
            raise InputError(f"{name['h']} must be a spacing in (0, {scale:g}] (the "
                             f"domain's size), got {h!r}")
        changes["h_path"] = h
        changes["h_far"] = max(spec.h_far, h)
    if directions is not None and kind == "plane":
        if isinstance(directions, bool) or not isinstance(directions, int) or not (
                8 <= directions <= 65536):
            raise InputError(f"{name['directions']} must be an integer in [8, 65536], got "
                             f"{directions!r}")
        changes["directions"] = directions
    return dataclasses.replace(spec, **changes) if changes else spec


def certify(
    metric: Metric | str,
    start: Any,
    goal: Any,
    settings: CertifySettings | str | None = None,
    *,
    path: Any = None,
    time_limit: float | None = None,
    strict: bool = False,
) -> Certificate:
    """Certified interval ``lower <= d(start, goal) <= upper``, by the certificate the
    metric allows (`certificate_kind`).

    ``start``, ``goal``: points ``(dim,)`` in the domain. ``settings``: the certificate's
    settings (`MeshSpec` in 2-D, `NDSpec` in 3-D and up, `ConformalSpec` for a conformal
    metric), or a preset name (``"coarse"``, ``"default"`` (also for None), ``"fine"``;
    ``"p2"`` in 3-D and up). ``path`` ``(n+1, dim)``: a curve from start to goal for the
    upper bound (default: solved with `solvers.solve_geodesic`). ``time_limit`` (seconds,
    2-D): no new refinement round starts after it. Raises `InputError` for bad input, or
    settings of another certificate's type. ``strict=True`` raises
    [`SolverError`][solvers.SolverError] unless the status is ``CERTIFIED`` (the interval
    is proven either way)."""
    m = as_metric(metric)
    kind = _kind(m)
    if settings is None or isinstance(settings, str):
        settings = _settings(m, settings or "default", None, None, None, None)
    elif not isinstance(settings, _SETTINGS[kind]):
        raise InputError(f"{m.name} gets the {kind} certificate, whose settings are a "
                         f"{_SETTINGS[kind].__name__}, not a {type(settings).__name__}")
    res: Certificate
    if kind == "conformal":
        from solvers.certificates.conformal.split import certify_conformal_best

        assert isinstance(settings, ConformalSpec)
        res = certify_conformal_best(m, start, goal, settings, path=path)
    elif kind == "nd":
        from solvers.certificates.nd.certificate import certify_nd

        assert isinstance(settings, NDSpec)
        res = certify_nd(m, start, goal, settings, path=path)
    else:
        from solvers.certificates.plane.certificate import certify_plane

        assert isinstance(settings, MeshSpec)
        res = certify_plane(m, start, goal, settings, path=path, time_limit=time_limit)
    return res.strict() if strict else res
