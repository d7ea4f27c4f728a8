"""Affine-arithmetic enclosures of lowered CasADi programs over boxes (numpy float64).

`enclose_affine` runs a lowered program (`finsler.lowering`) on boxes
``[lo, hi]`` with every scalar an affine form ``c + sum_k a_k eps_k + [-e, e]``: the noise
symbols ``eps_k in [-1, 1]`` are the box's inputs (``q_k = mid_k + rad_k eps_k``), ``e``
collects what is not linear. Beside it runs the natural interval extension
(`finsler.enclosures.intervals.Interval`); each value's interval is the intersection of both.
Correlations between the inputs survive through the program, so a chain of rotations (robot
kinematics) is enclosed to second order in the box's width, where the natural extension
loses first order to wrapping: on the Panda pole factor, boxes of 0.1 rad, the lower
bound is within about 1 % of the true minimum instead of 12 %.

Rules (``rad = sum |a_k| + e``):

- ``x +- y``, constants: exact in the forms;
- ``x * y``: ``c_x c_y + c_x a_y + c_y a_x``, error ``|c_x| e_y + |c_y| e_x + rad_x rad_y``
  (``x * x``: the square of the noise lies in ``[0, rad**2]``, half of it moves the
  centre);
- unary ``g`` (``sin``, ``cos``, ``sqrt``, constant powers): first-order Taylor form at the
  centre, ``g(c) + g'(c) (x - c)``, remainder ``max |g''| rad**2 / 2`` with ``max |g''|``
  an interval enclosure over the value's range; where that is not finite (a power near 0)
  the form falls back to the interval;
- ``abs``: the form or its negation where the sign is certain, else the Chebyshev line over
  the value's interval ``[l, u]`` (slope ``(u + l) / (u - l)``, error ``-u l / (u - l)``);
  ``max(a, b) = (a + b + |a - b|) / 2``, ``min`` likewise;
- signs and truth values (``sign``, comparisons, ``and``/``or``/``not``): the natural
  interval, no correlations; ``if_else_zero(c, a)`` keeps ``a``'s form where ``c`` is
  certainly true.

Every float64 operation on the forms adds ``8 ulp`` of the magnitudes it combined to ``e``
(16 for the elementary functions, whose numpy errors are documented at <= 4 ulp), so the
enclosure holds in exact arithmetic. Operations without an affine rule raise
`NotImplementedError`: callers fall back to `finsler.enclosures.intervals.enclose`.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from finsler.enclosures.intervals import Interval, _certainly, _IntervalBackend
from finsler.lowering import LoweredFunction

__all__ = ["affine_forms", "enclose_affine"]

_U = 2.0**-53
_TINY = 1e-300
_IV = _IntervalBackend()


def _slack(*mags: Any, ulps: float = 8.0) -> Any:
    total = _TINY
    for m in mags:
        total = total + np.abs(m)
    return ulps * _U * total


class _Affine:
    """``c + a . eps + [-e, e]`` and an interval ``iv`` of the same value, per box."""

    __slots__ = ("a", "c", "e", "iv")
    __array_ufunc__ = None

    def __init__(self, c: Any, a: Any, e: Any, iv: Interval) -> None:
        self.c, self.a, self.e = c, a, e
        rad = self.radius()
        with np.errstate(invalid="ignore", over="ignore"):
            lo = c - rad - _slack(c, rad)
            hi = c + rad + _slack(c, rad)
        ok = np.isfinite(lo) & np.isfinite(hi)
        self.iv = Interval(np.where(ok, np.maximum(iv.lo, lo), iv.lo),
                           np.where(ok, np.minimum(iv.hi, hi), iv.hi))

    def radius(self) -> Any:
        with np.errstate(invalid="ignore", over="ignore"):
            return (np.sum(np.abs(self.a), axis=-1) + self.e) * (1.0 + 8.0 * _U)

    @staticmethod
    def from_interval(iv: Interval, n: int) -> _Affine:
        """The form of a value known only by its interval (no correlations)."""
        with np.errstate(invalid="ignore", over="ignore"):
            c = 0.5 * iv.lo + 0.5 * iv.hi
            e = np.maximum(iv.hi - c, c - iv.lo) * (1.0 + 8.0 * _U) + _slack(c)
        c = np.where(np.isfinite(e), c, 0.0)
        e = np.where(np.isfinite(e), e, np.inf)
        return _Affine(c, np.zeros((*np.shape(c), n)), e, iv)

    # arithmetic -------------------------------------------------------------------------
    def __neg__(self) -> _Affine:
        return _Affine(-self.c, -self.a, self.e, -self.iv)

    def __add__(self, other: Any) -> _Affine:
        if isinstance(other, _Affine):
            c = self.c + other.c
            a = self.a + other.a
            e = self.e + other.e + _slack(c, np.sum(np.abs(a), axis=-1), self.e)
            return _Affine(c, a, e, self.iv + other.iv)
        k = float(other)
        c = self.c + k
        return _Affine(c, self.a, self.e + _slack(c), self.iv + k)

    __radd__ = __add__

    def __sub__(self, other: Any) -> _Affine:
        return self + (-other)

    def __rsub__(self, other: Any) -> _Affine:
        return (-self) + other

    def __mul__(self, other: Any) -> _Affine:
        if other is self:
            rad = self.radius()
            half = 0.5 * rad * rad
            c = self.c * self.c + half
            a = 2.0 * self.c[..., None] * self.a
            e = (half + 2.0 * np.abs(self.c) * self.e) * (1.0 + 8.0 * _U) + _slack(
                c, np.sum(np.abs(a), axis=-1), half)
            return _Affine(c, a, e, self.iv.square())
        if isinstance(other, _Affine):
            rx, ry = self.radius(), other.radius()
            c = self.c * other.c
            a = self.c[..., None] * other.a + other.c[..., None] * self.a
            e = (np.abs(self.c) * other.e + np.abs(other.c) * self.e + rx * ry) * (
                1.0 + 8.0 * _U) + _slack(c, np.sum(np.abs(a), axis=-1))
            return _Affine(c, a, e, self.iv * other.iv)
        k = float(other)
        c = k * self.c
        a = k * self.a
        e = abs(k) * self.e * (1.0 + 8.0 * _U) + _slack(c, np.sum(np.abs(a), axis=-1))
        return _Affine(c, a, e, self.iv * k)

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> _Affine:
        if isinstance(other, _Affine):
            return self * _unary(other, "pow", -1.0)
        return self * (1.0 / float(other)) if float(other) != 0.0 else _whole(self)

    def __rtruediv__(self, other: Any) -> _Affine:
        return _unary(self, "pow", -1.0) * float(other)


def _whole(x: _Affine) -> _Affine:
    return _Affine.from_interval(Interval(np.full_like(x.c, -np.inf),
                                          np.full_like(x.c, np.inf)), x.a.shape[-1])


def _unary(x: _Affine, name: str, p: float = 0.0) -> _Affine:
    """``g(x)`` by its first-order Taylor form at the centre ``c``; the remainder's
    ``max |g''|`` over the hull of the range and ``c``."""
    n = x.a.shape[-1]
    hull = Interval(np.minimum(x.iv.lo, x.c), np.maximum(x.iv.hi, x.c))
    with np.errstate(all="ignore"):
        if name == "sin":
            gc, dg, m2 = np.sin(x.c), np.cos(x.c), _IV.sin(hull).magnitude()
            natural = _IV.sin(x.iv)
        elif name == "cos":
            gc, dg, m2 = np.cos(x.c), -np.sin(x.c), _IV.cos(hull).magnitude()
            natural = _IV.cos(x.iv)
        elif name == "pow":
            gc, dg = x.c**p, p * x.c ** (p - 1.0)
            if p == 2.0:
                m2 = np.full_like(x.c, 2.0)
            elif p == round(p) and p >= 0:
                m2 = abs(p * (p - 1.0)) * hull.power(p - 2.0).magnitude()
            else:  # x ** (p - 2) on x > 0 only: a range reaching 0 has no finite bound
                m2 = np.where(hull.lo > 0.0,
                              abs(p * (p - 1.0)) * hull.power(p - 2.0).magnitude(), np.inf)
            natural = x.iv.power(p) if p != -1.0 else x.iv.reciprocal()
        elif name == "sqrt":
            gc, dg = np.sqrt(x.c), 0.5 / np.sqrt(x.c)
            m2 = np.where(hull.lo > 0.0, 0.25 * hull.power(-1.5).magnitude(), np.inf)
            natural = _IV.sqrt(x.iv)
        else:  # pragma: no cover - the backend only calls the names above
            raise NotImplementedError(name)
        rad = x.radius()
        a = dg[..., None] * x.a
        e = (np.abs(dg) * x.e + 0.5 * m2 * rad * rad) * (1.0 + 8.0 * _U) + _slack(
            gc, dg * rad, ulps=16.0) + _slack(np.sum(np.abs(a), axis=-1))
    good = np.isfinite(gc) & np.isfinite(e) & np.all(np.isfinite(a), axis=-1)
    if np.all(good):
        return _Affine(gc, a, e, natural)
    fallback = _Affine.from_interval(natural, n)
    return _Affine(np.where(good, gc, fallback.c), np.where(good[..., None], a, fallback.a),
                   np.where(good, e, fallback.e), natural)


class _AffineBackend:
    """The operations of lowered programs that have an affine rule."""

    @staticmethod
    def sin(x: _Affine) -> _Affine:
        return _unary(x, "sin")

    @staticmethod
    def cos(x: _Affine) -> _Affine:
        return _unary(x, "cos")

    @staticmethod
    def sqrt(x: _Affine) -> _Affine:
        return _unary(x, "sqrt")

    @staticmethod
    def pow(x: Any, p: Any) -> _Affine:
        if isinstance(p, _Affine) or not isinstance(x, _Affine):
            raise NotImplementedError("affine enclosure of a power with a variable exponent")
        return _unary(x, "pow", float(p))

    @staticmethod
    def abs(x: Any) -> Any:
        if not isinstance(x, _Affine):
            return abs(float(x))
        return _abs(x)

    @staticmethod
    def maximum(a: Any, b: Any) -> Any:
        if not (isinstance(a, _Affine) or isinstance(b, _Affine)):
            return max(float(a), float(b))
        return _with_natural((a + b + _BACKEND.abs(a - b)) * 0.5, "maximum", a, b)

    @staticmethod
    def minimum(a: Any, b: Any) -> Any:
        if not (isinstance(a, _Affine) or isinstance(b, _Affine)):
            return min(float(a), float(b))
        return _with_natural((a + b - _BACKEND.abs(a - b)) * 0.5, "minimum", a, b)

    # if_else_zero keeps its argument's form where the condition is certain; the other
    # signs and truth values: the natural interval, correlations dropped (__getattr__)
    def if_else_zero(self, c: Any, a: Any) -> Any:
        hull = _discrete("if_else_zero", c, a)
        if not isinstance(hull, _Affine) or not isinstance(a, _Affine):
            return hull
        true = _certainly(c.iv if isinstance(c, _Affine) else Interval(float(c)))[0]
        true = np.broadcast_to(true, hull.c.shape)
        return _Affine(np.where(true, a.c, hull.c), np.where(true[..., None], a.a, hull.a),
                       np.where(true, a.e, hull.e), hull.iv)

    def __getattr__(self, name: str) -> Any:
        if name in _DISCRETE:
            return functools.partial(_discrete, name)
        raise NotImplementedError(f"affine enclosure of the CasADi operation {name!r} is not "
                                  "implemented")


#: operations whose values are signs or truth values (enclosed by their natural interval)
_DISCRETE = frozenset({"sign", "lt", "le", "eq", "ne", "logical_not", "logical_and",
                       "logical_or"})


def _abs(x: _Affine) -> _Affine:
    """``|x|``: the form itself or its negation where the sign is certain; across 0 the
    Chebyshev line ``alpha x + D / 2 +- D / 2`` with ``alpha = (u + l) / (u - l)`` over the
    value's interval ``[l, u]`` (``|x| - alpha x`` is convex, 0 at 0 and at most ``D`` at
    the ends)."""
    lo, hi = x.iv.lo, x.iv.hi
    natural = _IV.abs(x.iv)
    with np.errstate(all="ignore"):
        across = (lo < 0.0) & (hi > 0.0)
        alpha = np.where(across, (hi + lo) / np.where(across, hi - lo, 1.0),
                         np.where(lo >= 0.0, 1.0, -1.0))
        alpha = np.clip(alpha, -1.0, 1.0)
        # the residual's largest value at the ends, rounded up (0 where the sign is certain)
        d = np.where(across, np.maximum(hi - alpha * hi, -lo - alpha * lo), 0.0)
        d = np.where(across, d * (1.0 + 8.0 * _U) + _slack(hi, lo), 0.0)
        c = alpha * x.c + 0.5 * d
        a = alpha[..., None] * x.a
        e = (np.abs(alpha) * x.e + 0.5 * d) * (1.0 + 8.0 * _U) + _slack(
            c, np.sum(np.abs(a), axis=-1), d)
    good = np.isfinite(c) & np.isfinite(e) & np.all(np.isfinite(a), axis=-1)
    if np.all(good):
        return _Affine(c, a, e, natural)
    fallback = _Affine.from_interval(natural, x.a.shape[-1])
    return _Affine(np.where(good, c, fallback.c), np.where(good[..., None], a, fallback.a),
                   np.where(good, e, fallback.e), natural)


def _ivs(args: tuple[Any, ...]) -> list[Interval]:
    return [v.iv if isinstance(v, _Affine) else Interval(np.float64(v)) for v in args]


def _with_natural(form: _Affine, name: str, *args: Any) -> _Affine:
    """``form`` with its interval cut to the natural extension of ``name`` on ``args``."""
    natural = getattr(_IV, name)(*_ivs(args))
    return _Affine(form.c, form.a, form.e, form.iv.intersect(natural))


def _discrete(name: str, *args: Any) -> Any:
    """A sign or truth value by the interval backend's rule on the arguments' intervals."""
    forms = [v for v in args if isinstance(v, _Affine)]
    out = getattr(_IV, name)(*_ivs(args))
    if not forms:
        return float(out.lo)
    shape = forms[0].c.shape
    out = Interval(np.broadcast_to(out.lo, shape), np.broadcast_to(out.hi, shape))
    return _Affine.from_interval(out, forms[0].a.shape[-1])


_BACKEND = _AffineBackend()


def enclose_affine(fn: LoweredFunction, lo: Any, hi: Any) -> list[Interval]:
    """Enclosures of the outputs of a one-input ``fn`` over boxes ``[lo, hi]`` ``(N, n)``:
    one `Interval` of shape ``(N,)`` per output coordinate (all outputs, in order),
    each the intersection of the affine and the natural interval enclosures.

    Raises `NotImplementedError` for a program with an operation that has no affine
    rule (callers then use `finsler.enclosures.intervals.enclose`), ``ValueError`` for bad
    shapes."""
    return [v.iv for v in _run(fn, np.asarray(lo, np.float64), np.asarray(hi, np.float64))[2]]


def affine_forms(fn: LoweredFunction, lo: Any, hi: Any) -> tuple[
        np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray, np.ndarray, Interval]]]:
    """The affine forms themselves: ``(mid, rad, forms)`` with each input coordinate
    ``q_k = mid_k + rad_k eps_k`` (``eps_k in [-1, 1]``, a superset of the box) and one
    ``(c, a, e, iv)`` per output coordinate: for every point of the box the value lies in
    ``c + a . eps + [-e, e]`` (``c`` ``(N,)``, ``a`` ``(N, n)``, ``e`` ``(N,)``, the float
    errors of the forms' own arithmetic included) and in the interval ``iv``. Callers
    maximise the linear part over sets smaller than the box (a simplex inside it). Same
    errors as `enclose_affine`."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    mid, rad, outs = _run(fn, lo, hi)
    return mid, rad, [(v.c, v.a, v.e, v.iv) for v in outs]


def _run(fn: LoweredFunction, lo: np.ndarray, hi: np.ndarray) -> tuple[
        np.ndarray, np.ndarray, list[_Affine]]:
    if fn.n_in != 1 or lo.ndim != 2 or lo.shape != hi.shape or lo.shape[1] != fn.in_sizes[0]:
        raise ValueError(f"{fn.name}: enclose_affine needs one input of shape (N, "
                         f"{fn.in_sizes[0]}), got {lo.shape} / {hi.shape}")
    if np.any(lo > hi):
        raise ValueError(f"{fn.name}: a box has lo > hi")
    n = lo.shape[1]
    mid = 0.5 * lo + 0.5 * hi
    # eps_k in [-1, 1] spans [mid - rad, mid + rad], a superset of [lo, hi] (rad rounded up)
    rad = np.maximum(hi - mid, mid - lo) * (1.0 + 4.0 * _U)
    cols = []
    for j in range(n):
        a = np.zeros((lo.shape[0], n))
        a[:, j] = rad[:, j]
        cols.append(_Affine(mid[:, j], a, np.zeros(lo.shape[0]),
                            Interval(lo[:, j], hi[:, j])))
    outs = fn.run(_BACKEND, [cols])
    result = []
    for o in outs:
        for v in o:
            if isinstance(v, _Affine):
                result.append(v)
            else:  # a constant output
                k = np.full(lo.shape[0], float(v))
                result.append(_Affine(k, np.zeros((lo.shape[0], n)), np.zeros(lo.shape[0]),
                                      Interval(k)))
    return mid, rad, result


class AffineInput:
    """Helpers to run a lowered program on caller-built affine forms (correlated inputs)."""

    @staticmethod
    def form(c: Any, a: Any, e: Any, lo: Any, hi: Any) -> _Affine:
        """The form ``c + a . eps + [-e, e]`` of a value known to lie in ``[lo, hi]``."""
        return _Affine(np.asarray(c, float), np.asarray(a, float), np.asarray(e, float),
                       Interval(np.asarray(lo, float), np.asarray(hi, float)))

    @staticmethod
    def run(fn: LoweredFunction, columns: list[list[_Affine]]) -> list[_Affine]:
        """All output coordinates of ``fn`` on the input forms ``columns[i][j]``."""
        outs = fn.run(_BACKEND, columns)
        n = columns[0][0].a.shape[-1]
        size = columns[0][0].c.shape
        res = []
        for o in outs:
            for v in o:
                if isinstance(v, _Affine):
                    res.append(v)
                else:
                    k = np.full(size, float(v))
                    res.append(_Affine(k, np.zeros((*size, n)), np.zeros(size), Interval(k)))
        return res
