"""Interval enclosures of CasADi expressions, vectorised over boxes (numpy float64).

`enclose` runs the straight-line program of a lowered CasADi function
(`finsler.lowering`) with every scalar replaced by an `Interval` ``[lo, hi]``
of arrays: the result encloses every value the function takes on the input boxes, one box
per array element. Rounding is outward: every operation widens its result by a few units
in the last place (two for the correctly rounded ``+ - * /`` and ``sqrt``, sixteen for
numpy's ``exp``, ``log``, ``sin``, ... whose documented errors are at most 4 ulp), so the
enclosure holds in exact arithmetic, not only up to rounding.

Operations whose result is not defined somewhere on the box (a division by an interval
containing 0, ``log`` of a non-positive number, 0 x inf) give the whole real line
``[-inf, inf]``: the caller sees an infinite bound, never a wrong finite one. ``sqrt`` and
non-integer powers are taken on the part of the box where they are defined (the true
argument of a metric's square root is >= 0; only the enclosure may dip below).

Why by hand: the enclosures are needed for millions of boxes at once (every triangle of a
certification mesh x every sampled direction); the maintained interval libraries
(mpmath's ``iv``, python-flint's ``arb``) are scalar, three orders of magnitude too slow
here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from finsler.lowering import LoweredFunction

__all__ = ["Interval", "enclose", "isqrt"]

_EPS = 2.0**-52
_TINY = 1e-300
#: Widening of correctly rounded operations and of numpy's transcendental functions (ulp).
_ULP_EXACT = 2.0
_ULP_LIBM = 16.0


def _down(x: np.ndarray, ulps: float) -> np.ndarray:
    """``x`` minus at least ``ulps / 2`` units in its last place (in place on a temporary:
    four array passes, several times cheaper than ``np.nextafter``)."""
    with np.errstate(invalid="ignore", over="ignore"):
        t = np.abs(x)
        t *= -ulps * _EPS
        t -= _TINY
        t += x
    return t


def _up(x: np.ndarray, ulps: float) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        t = np.abs(x)
        t *= ulps * _EPS
        t += _TINY
        t += x
    return t


class Interval:
    """Arrays ``lo <= hi`` (broadcastable) enclosing a real quantity elementwise.

    Arithmetic with other intervals and with float64 constants (taken as exact) rounds
    outward; NaN bounds are replaced by the whole line.
    """

    __slots__ = ("hi", "lo")
    __array_ufunc__ = None  # numpy scalars on the left defer to Interval's operators

    def __init__(self, lo: Any, hi: Any = None) -> None:
        lo = np.asarray(lo, dtype=np.float64)
        hi = lo if hi is None else np.asarray(hi, dtype=np.float64)
        # a sum is NaN if an element is (or if inf - inf occurs): one pass without a
        # temporary, where the two masks and copies of np.where cost five (every operation
        # of an enclosure builds an Interval: a third of the time of certify's bounds)
        self.lo = np.where(np.isnan(lo), -np.inf, lo) if np.isnan(np.sum(lo)) else lo
        self.hi = np.where(np.isnan(hi), np.inf, hi) if np.isnan(np.sum(hi)) else hi

    @staticmethod
    def _rounded(lo: np.ndarray, hi: np.ndarray, ulps: float = _ULP_EXACT) -> Interval:
        return Interval(_down(lo, ulps), _up(hi, ulps))

    def __repr__(self) -> str:
        return f"Interval({self.lo!r}, {self.hi!r})"

    @property
    def mid(self) -> np.ndarray:
        return 0.5 * self.lo + 0.5 * self.hi

    def contains(self, x: Any) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        return (self.lo <= x) & (x <= self.hi)

    def intersect(self, other: Interval) -> Interval:
        """Both enclose the same quantity: the tighter of the two bounds on each side."""
        return Interval(np.maximum(self.lo, other.lo), np.minimum(self.hi, other.hi))

    def magnitude(self) -> np.ndarray:
        """``max |x|`` over the interval."""
        return np.maximum(np.abs(self.lo), np.abs(self.hi))

    # arithmetic ---------------------------------------------------------------------
    def __neg__(self) -> Interval:
        return Interval(-self.hi, -self.lo)

    def __pos__(self) -> Interval:
        return self

    def __add__(self, other: Any) -> Interval:
        o = _iv(other)
        with np.errstate(invalid="ignore"):
            return Interval._rounded(self.lo + o.lo, self.hi + o.hi)

    __radd__ = __add__

    def __sub__(self, other: Any) -> Interval:
        o = _iv(other)
        with np.errstate(invalid="ignore"):
            return Interval._rounded(self.lo - o.hi, self.hi - o.lo)

    def __rsub__(self, other: Any) -> Interval:
        return _iv(other) - self

    def __mul__(self, other: Any) -> Interval:
        if other is self:
            return self.square()
        o = _iv(other)
        with np.errstate(invalid="ignore"):
            p = (self.lo * o.lo, self.lo * o.hi, self.hi * o.lo, self.hi * o.hi)
        lo = np.minimum(np.minimum(p[0], p[1]), np.minimum(p[2], p[3]))
        hi = np.maximum(np.maximum(p[0], p[1]), np.maximum(p[2], p[3]))
        return Interval._rounded(lo, hi)  # NaN (0 x inf) -> whole line

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> Interval:
        return self * _iv(other).reciprocal()

    def __rtruediv__(self, other: Any) -> Interval:
        return _iv(other) * self.reciprocal()

    def reciprocal(self) -> Interval:
        straddles = (self.lo <= 0.0) & (self.hi >= 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lo, hi = 1.0 / self.hi, 1.0 / self.lo
        # 1 / (a subnormal) overflows: the true value lies beyond the largest float, which is
        # then the bound on the side towards 0 (inf would exclude the true value)
        big = np.finfo(float).max
        lo = np.where(np.isposinf(lo) & (self.hi != 0.0), big, lo)
        hi = np.where(np.isneginf(hi) & (self.lo != 0.0), -big, hi)
        out = Interval._rounded(lo, hi)
        return Interval(np.where(straddles, -np.inf, out.lo), np.where(straddles, np.inf, out.hi))

    def square(self) -> Interval:
        a, b = self.lo * self.lo, self.hi * self.hi
        straddles = (self.lo < 0.0) & (self.hi > 0.0)
        lo = np.where(straddles, 0.0, np.minimum(a, b))
        return Interval(np.maximum(_down(lo, _ULP_EXACT), 0.0), _up(np.maximum(a, b), _ULP_EXACT))

    def power(self, p: float) -> Interval:
        if p == 2.0:
            return self.square()
        # an integer exponent, however large: x ** n is defined for negative x too (a cap
        # here once sent x ** 65 to the x >= 0 route below, a wrong enclosure for x < 0)
        if math.isfinite(p) and p == round(p):
            n = round(p)
            if n == 0:
                return Interval(np.ones_like(self.lo))
            if n < 0:
                return self.power(-n).reciprocal()
            e = float(n)  # (a Python int beyond int64 would not convert)
            if n % 2 == 0:
                mag = self.magnitude()
                straddles = (self.lo < 0.0) & (self.hi > 0.0)
                small = np.where(straddles, 0.0, np.minimum(np.abs(self.lo), np.abs(self.hi)))
                with np.errstate(over="ignore"):  # beyond the largest float: inf, soundly
                    small, mag = small**e, mag**e
                return Interval(np.maximum(_down(small, n * _ULP_EXACT), 0.0),
                                _up(mag, n * _ULP_EXACT))
            with np.errstate(over="ignore"):
                a, b = self.lo**e, self.hi**e
            return Interval._rounded(a, b, n * _ULP_EXACT)
        # non-integer power: on the part of the box where x >= 0
        lo = np.maximum(self.lo, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = lo**p, self.hi**p
        if p > 0:
            return Interval._rounded(a, b, _ULP_LIBM)
        return Interval._rounded(b, a, _ULP_LIBM)


def _iv(x: Any) -> Interval:
    return x if isinstance(x, Interval) else Interval(x)


def _monotone(fn: Any, x: Any, increasing: bool = True) -> Interval:
    x = _iv(x)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a, b = fn(x.lo), fn(x.hi)
    return Interval._rounded(a, b, _ULP_LIBM) if increasing else Interval._rounded(
        b, a, _ULP_LIBM)


def _contains_point(x: Interval, phase: float) -> np.ndarray:
    """Whether ``[lo, hi]`` contains ``phase + 2 pi k`` for some integer ``k`` (in doubt:
    yes)."""
    two_pi = 2.0 * math.pi
    # the first candidate at or above lo, with the same slack as on the hi side: the rounding
    # of (lo - phase) / two_pi grows with |lo| (near 1e9 a fixed 1e-9 in k once skipped an
    # extremum 2e-7 above lo, and sin's upper bound came out 4e-15 below 1)
    k = np.ceil((x.lo - phase - 1e-9 * (1.0 + np.abs(x.lo))) / two_pi)
    return (phase + two_pi * k <= x.hi + 1e-9 * (1.0 + np.abs(x.hi))) | (
        x.hi - x.lo >= two_pi)


def _certainly(x: Any) -> tuple[np.ndarray, np.ndarray]:
    """Where the truth value ``x`` (an interval; nonzero = true) is certainly true (0 not
    in it) and certainly false (exactly 0)."""
    x = _iv(x)
    return (x.lo > 0.0) | (x.hi < 0.0), (x.lo == 0.0) & (x.hi == 0.0)


class _IntervalBackend:
    """Operations of the lowered programs on `Interval` values."""

    @staticmethod
    def exp(x: Any) -> Interval:
        out = _monotone(np.exp, x)
        return Interval(np.maximum(out.lo, 0.0), out.hi)

    @staticmethod
    def log(x: Any) -> Interval:
        x = _iv(x)
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = np.log(np.maximum(x.lo, 0.0)), np.log(x.hi)
        out = Interval._rounded(a, b, _ULP_LIBM)
        return Interval(np.where(x.lo <= 0.0, -np.inf, out.lo), out.hi)

    @staticmethod
    def sqrt(x: Any) -> Interval:
        x = _iv(x)
        with np.errstate(invalid="ignore"):
            a, b = np.sqrt(np.maximum(x.lo, 0.0)), np.sqrt(x.hi)
        return Interval(np.maximum(_down(a, _ULP_EXACT), 0.0), _up(b, _ULP_EXACT))

    @staticmethod
    def sin(x: Any) -> Interval:
        return _IntervalBackend._periodic(np.sin, _iv(x), 0.5 * math.pi, 1.5 * math.pi)

    @staticmethod
    def cos(x: Any) -> Interval:
        return _IntervalBackend._periodic(np.cos, _iv(x), 0.0, math.pi)

    @staticmethod
    def _periodic(fn: Any, x: Interval, at_max: float, at_min: float) -> Interval:
        with np.errstate(invalid="ignore"):  # sin(inf): NaN, the box gets [-1, 1] below
            a, b = fn(x.lo), fn(x.hi)
        out = Interval._rounded(np.minimum(a, b), np.maximum(a, b), _ULP_LIBM)
        lo = np.where(_contains_point(x, at_min), -1.0, np.maximum(out.lo, -1.0))
        hi = np.where(_contains_point(x, at_max), 1.0, np.minimum(out.hi, 1.0))
        finite = np.isfinite(x.lo) & np.isfinite(x.hi)
        return Interval(np.where(finite, lo, -1.0), np.where(finite, hi, 1.0))

    @staticmethod
    def tanh(x: Any) -> Interval:
        out = _monotone(np.tanh, x)
        return Interval(np.maximum(out.lo, -1.0), np.minimum(out.hi, 1.0))

    @staticmethod
    def atan(x: Any) -> Interval:
        return _monotone(np.arctan, x)

    @staticmethod
    def asin(x: Any) -> Interval:
        x = _iv(x)
        return _monotone(np.arcsin, Interval(np.maximum(x.lo, -1.0), np.minimum(x.hi, 1.0)))

    @staticmethod
    def acos(x: Any) -> Interval:
        x = _iv(x)
        return _monotone(np.arccos, Interval(np.maximum(x.lo, -1.0), np.minimum(x.hi, 1.0)),
                         increasing=False)

    @staticmethod
    def sinh(x: Any) -> Interval:
        return _monotone(np.sinh, x)

    @staticmethod
    def cosh(x: Any) -> Interval:
        x = _iv(x)
        return _monotone(np.cosh, _IntervalBackend.abs(x))

    @staticmethod
    def asinh(x: Any) -> Interval:
        return _monotone(np.arcsinh, x)

    @staticmethod
    def log1p(x: Any) -> Interval:
        x = _iv(x)
        out = _monotone(np.log1p, x)
        return Interval(np.where(x.lo <= -1.0, -np.inf, out.lo), out.hi)

    @staticmethod
    def expm1(x: Any) -> Interval:
        return _monotone(np.expm1, x)

    @staticmethod
    def erf(x: Any) -> Interval:
        from scipy.special import erf

        out = _monotone(erf, x)
        return Interval(np.maximum(out.lo, -1.0), np.minimum(out.hi, 1.0))

    @staticmethod
    def floor(x: Any) -> Interval:
        x = _iv(x)
        return Interval(np.floor(x.lo), np.floor(x.hi))

    @staticmethod
    def ceil(x: Any) -> Interval:
        x = _iv(x)
        return Interval(np.ceil(x.lo), np.ceil(x.hi))

    @staticmethod
    def abs(x: Any) -> Interval:
        x = _iv(x)
        straddles = (x.lo < 0.0) & (x.hi > 0.0)
        lo = np.where(straddles, 0.0, np.minimum(np.abs(x.lo), np.abs(x.hi)))
        return Interval(lo, x.magnitude())

    @staticmethod
    def sign(x: Any) -> Interval:
        x = _iv(x)
        return Interval(np.sign(x.lo), np.sign(x.hi))

    @staticmethod
    def hypot(a: Any, b: Any) -> Interval:
        return _IntervalBackend.sqrt(_iv(a).square() + _iv(b).square())

    @staticmethod
    def minimum(a: Any, b: Any) -> Interval:
        a, b = _iv(a), _iv(b)
        return Interval(np.minimum(a.lo, b.lo), np.minimum(a.hi, b.hi))

    @staticmethod
    def maximum(a: Any, b: Any) -> Interval:
        a, b = _iv(a), _iv(b)
        return Interval(np.maximum(a.lo, b.lo), np.maximum(a.hi, b.hi))

    @staticmethod
    def pow(a: Any, b: Any) -> Interval:
        if not isinstance(b, Interval):
            return _iv(a).power(float(b))
        if np.all(b.lo == b.hi) and np.unique(b.lo).size == 1:
            return _iv(a).power(float(b.lo.flat[0]))
        return _IntervalBackend.exp(b * _IntervalBackend.log(a))

    # comparisons give [1, 1] (true on the whole box), [0, 0] (false) or [0, 1]
    @staticmethod
    def _truth(true: np.ndarray, false: np.ndarray) -> Interval:
        return Interval(np.where(true, 1.0, 0.0), np.where(false, 0.0, 1.0))

    @staticmethod
    def lt(a: Any, b: Any) -> Interval:
        a, b = _iv(a), _iv(b)
        return _IntervalBackend._truth(a.hi < b.lo, a.lo >= b.hi)

    @staticmethod
    def le(a: Any, b: Any) -> Interval:
        a, b = _iv(a), _iv(b)
        return _IntervalBackend._truth(a.hi <= b.lo, a.lo > b.hi)

    @staticmethod
    def eq(a: Any, b: Any) -> Interval:
        a, b = _iv(a), _iv(b)
        point = (a.lo == a.hi) & (b.lo == b.hi) & (a.lo == b.lo)
        return _IntervalBackend._truth(point, (a.hi < b.lo) | (a.lo > b.hi))

    @staticmethod
    def ne(a: Any, b: Any) -> Interval:
        e = _IntervalBackend.eq(a, b)
        return Interval(1.0 - e.hi, 1.0 - e.lo)

    @staticmethod
    def logical_not(a: Any) -> Interval:
        a = _iv(a)
        return _IntervalBackend._truth((a.lo == 0.0) & (a.hi == 0.0), (a.lo > 0.0) | (a.hi < 0.0))

    @staticmethod
    def logical_and(a: Any, b: Any) -> Interval:
        (ta, fa), (tb, fb) = _certainly(a), _certainly(b)
        return _IntervalBackend._truth(ta & tb, fa | fb)

    @staticmethod
    def logical_or(a: Any, b: Any) -> Interval:
        (ta, fa), (tb, fb) = _certainly(a), _certainly(b)
        return _IntervalBackend._truth(ta | tb, fa & fb)

    @staticmethod
    def if_else_zero(c: Any, a: Any) -> Interval:
        a = _iv(a)
        true, false = _certainly(c)
        lo = np.where(true, a.lo, np.where(false, 0.0, np.minimum(a.lo, 0.0)))
        hi = np.where(true, a.hi, np.where(false, 0.0, np.maximum(a.hi, 0.0)))
        return Interval(lo, hi)

    def __getattr__(self, name: str) -> Any:
        raise NotImplementedError(f"interval enclosure of the CasADi operation {name!r} is "
                                  "not implemented")


_BACKEND = _IntervalBackend()


def isqrt(x: Interval) -> Interval:
    """Enclosure of ``sqrt`` over ``x`` (on the part where ``x >= 0``)."""
    return _BACKEND.sqrt(x)


def enclose(fn: LoweredFunction, *boxes: Sequence[Interval] | Interval) -> tuple[Interval, ...]:
    """Enclosures of the outputs of ``fn`` over input boxes.

    Each input is either an `Interval` whose ``lo`` / ``hi`` have shape
    ``(N, n_i)`` (``N`` boxes; broadcastable along ``N``) or a sequence of ``n_i``
    intervals (one per coordinate). Returns one list of intervals per output, one interval
    per output coordinate, each of shape ``(N,)`` (broadcast).
    """
    if len(boxes) != fn.n_in:
        raise TypeError(f"{fn.name}: expected {fn.n_in} inputs, got {len(boxes)}")
    cols = []
    for k, (box, n) in enumerate(zip(boxes, fn.in_sizes, strict=True)):
        if isinstance(box, Interval):
            if box.lo.shape[-1] != n or box.hi.shape[-1] != n:
                raise ValueError(f"{fn.name}: input {k} must have last dimension {n}, got "
                                 f"{box.lo.shape}")
            if np.any(box.lo > box.hi):
                raise ValueError(f"{fn.name}: input {k} has lo > hi")
            cols.append([Interval(box.lo[..., j], box.hi[..., j]) for j in range(n)])
        else:
            if len(box) != n:
                raise ValueError(f"{fn.name}: input {k} needs {n} intervals, got {len(box)}")
            cols.append([_iv(c) for c in box])
    outs = fn.run(_BACKEND, cols)
    return tuple([_iv(c) for c in o] for o in outs)
