"""Coordinate domains: membership, uniform sampling, projection, IPOPT constraints.

Every domain works on batch-first arrays ``(N, dim)``; ``project`` accepts numpy
arrays or torch tensors (the torch path is differentiable and used inside the
actor's forward pass).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from finsler.errors import DomainError, InputError, short

__all__ = ["Box", "Disk", "Domain", "JointBox", "Product", "as_real", "describe_value", "is_torch"]


def is_torch(a: Any) -> bool:
    """True if ``a`` is a torch tensor (torch is imported lazily)."""
    mod = type(a).__module__
    return mod.startswith("torch")


#: How many characters of a refused value an error message quotes.
QUOTE_LIMIT = 80


def describe_value(value: Any) -> str:
    """``value`` for an error message: its type and a repr cut to `QUOTE_LIMIT`
    characters (``str '0.1,0.15'``, ``complex128 array of shape (2,)``)."""
    if isinstance(value, np.ndarray) or is_torch(value):
        dtype = str(value.dtype).replace("torch.", "")
        return f"a {dtype} array of shape {tuple(value.shape)}"
    return f"{type(value).__name__} {short(repr(value), QUOTE_LIMIT)}"


def as_real(x: Any, name: str, expect: str = "a real numeric array") -> Any:
    """``x`` as a float64 numpy array if it is a real numeric array-like (a number, a list,
    a tuple, a numpy array of integers or floats); a real floating torch tensor passes
    through unchanged. Anything else (strings, bytes, dicts, None, booleans, complex,
    object or ragged arrays) is an `InputError` naming ``name``, what was expected
    (``expect``) and what it got. Shapes are the caller's to check."""
    if is_torch(x):
        if x.is_complex() or not x.is_floating_point():
            raise InputError(f"{name} must be {expect}, got {describe_value(x)}")
        return x
    if x is None or isinstance(x, (str, bytes, dict, set, frozenset, bool, np.bool_)):
        raise InputError(f"{name} must be {expect}, got {describe_value(x)}")
    if isinstance(x, np.ndarray) and x.dtype == np.float64:
        return x
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError, OverflowError, RecursionError) as err:  # ragged, odd types
        raise InputError(f"{name} must be {expect}, got {describe_value(x)}") from err
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{name} must be {expect}, got {describe_value(x)}"
                         + ("" if isinstance(x, np.ndarray) else f" ({arr.dtype} values)"))
    return arr.astype(np.float64, copy=False)


def _as_batch(x: Any, dim: int, name: str, check_finite: bool = True) -> Any:
    """Validate shape ``(N, dim)`` or ``(dim,)`` (and finiteness unless ``check_finite`` is
    false, for callers that check their outputs instead); return a 2-D view."""
    x = as_real(x, name, f"a real numeric array of shape (N, {dim}) or ({dim},)")
    if is_torch(x):
        import torch

        if x.ndim not in (1, 2) or x.shape[-1] != dim:
            raise InputError(f"{name} must have shape (N, {dim}) or ({dim},), got {tuple(x.shape)}")
        if check_finite and not bool(torch.isfinite(x).all()):
            raise InputError(f"{name} contains NaN or inf")
        return x.reshape(-1, dim)
    if x.ndim not in (1, 2) or x.shape[-1] != dim:
        raise InputError(f"{name} must have shape (N, {dim}) or ({dim},), got {x.shape}")
    if check_finite and not np.all(np.isfinite(x)):
        raise InputError(f"{name} contains NaN or inf")
    return x.reshape(-1, dim)


class Domain(ABC):
    """A closed subset of R^dim in coordinates."""

    dim: int
    names: tuple[str, ...] = ()
    """Coordinate names (empty: unnamed; figures then say ``x0``, ``x1``, ...)."""

    @property
    def is_box(self) -> bool:
        """True if the domain is exactly its bounding box (`bounds`): every
        coordinate bounded on its own, so a solver may treat the constraints coordinate by
        coordinate (projected Newton); False for the disk."""
        return False

    @abstractmethod
    def contains(self, x: Any, tol: float = 1e-12) -> np.ndarray:
        """Membership of each row of ``x`` ``(N, dim)`` -> bool ``(N,)``."""

    @abstractmethod
    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` points drawn uniformly (w.r.t. Lebesgue measure) -> ``(n, dim)``."""

    @abstractmethod
    def project(self, x: Any) -> Any:
        """Nearest point of the domain (Euclidean) of each row; numpy or torch."""

    @abstractmethod
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Coordinate-wise bounds ``(low, high)`` (``-inf``/``inf`` where unbounded)."""

    @abstractmethod
    def constraints_sx(self, x: ca.SX) -> list[tuple[ca.SX, float, float]]:
        """Nonlinear constraints ``lb <= g(x) <= ub`` beyond the bounds, for IPOPT."""

    def describe(self) -> str:
        return type(self).__name__

    def check(self, x: Any, name: str = "point", tol: float = 1e-9) -> np.ndarray:
        """Validate shape and finiteness, and raise `DomainError` if outside."""
        xb = _as_batch(x, self.dim, name)
        xn = xb.detach().cpu().numpy() if is_torch(xb) else xb
        with np.errstate(over="ignore", invalid="ignore"):  # huge coordinates are outside
            inside = self.contains(xn, tol=tol)
        if not np.all(inside):
            bad = int(np.flatnonzero(~inside)[0])
            point = "(" + ", ".join(repr(float(v)) for v in xn[bad]) + ")"  # full precision
            where = f"{name} row {bad}" if xn.shape[0] > 1 else name
            if len(point) > 160:  # many coordinates: the first few
                point = point[:150] + "...)"
            raise DomainError(f"{where} = {point} lies outside the domain {self.describe()}")
        return xn

    def _sample_check(self, n: int) -> None:
        if not isinstance(n, (int, np.integer)) or n < 0:
            raise InputError(f"sample size must be a non-negative integer, got {n!r}")


@dataclass(frozen=True)
class Box(Domain):
    """Axis-aligned box ``low <= x <= high``."""

    low: tuple[float, ...]
    high: tuple[float, ...]
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.low, float), np.asarray(self.high, float)
        if lo.shape != hi.shape or lo.ndim != 1 or not np.all(lo < hi):
            raise InputError(f"Box needs low < high of equal length, got {self.low}, {self.high}")
        if not self.names:
            object.__setattr__(self, "names", tuple(f"x{i}" for i in range(lo.size)))

    @property
    def dim(self) -> int:  # type: ignore[override]
        return len(self.low)

    @property
    def is_box(self) -> bool:
        return True

    def describe(self) -> str:
        return "box " + " x ".join(f"[{a:g}, {b:g}]" for a, b in zip(self.low, self.high))

    def contains(self, x: Any, tol: float = 1e-12) -> np.ndarray:
        x = np.asarray(x, float).reshape(-1, self.dim)
        lo, hi = np.asarray(self.low), np.asarray(self.high)
        return np.all((x >= lo - tol) & (x <= hi + tol), axis=1)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        self._sample_check(n)
        lo, hi = np.asarray(self.low, float), np.asarray(self.high, float)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise InputError(f"cannot draw points uniformly from the unbounded {self.describe()}:"
                             " give the domain finite bounds (a box that covers where paths "
                             "go) to sample pairs or run the property checks")
        return rng.uniform(lo, hi, size=(n, self.dim))

    def project(self, x: Any) -> Any:
        if is_torch(x):
            import torch

            lo = torch.as_tensor(self.low, dtype=x.dtype, device=x.device)
            hi = torch.as_tensor(self.high, dtype=x.dtype, device=x.device)
            return torch.clamp(x, lo, hi)
        return np.clip(np.asarray(x, float), self.low, self.high)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.low, float), np.asarray(self.high, float)

    def constraints_sx(self, x: ca.SX) -> list[tuple[ca.SX, float, float]]:
        return []


@dataclass(frozen=True)
class JointBox(Box):
    """Joint-limit box of a robot arm (a [`Box`][finsler.domains.Box] with joint names)."""

    def describe(self) -> str:
        return f"joint-limit box ({self.dim} joints)"


@dataclass(frozen=True)
class Disk(Domain):
    """Closed 2-D disk ``|x - center| <= radius``."""

    radius: float = 1.0
    center: tuple[float, float] = (0.0, 0.0)
    names: tuple[str, ...] = ("x", "y")

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise InputError(f"Disk radius must be positive and finite, got {self.radius}")

    @property
    def dim(self) -> int:  # type: ignore[override]
        return 2

    def describe(self) -> str:
        c = self.center
        if c == (0.0, 0.0):
            return f"disk |p| <= {self.radius:g}"
        return f"disk |p - ({c[0]:g}, {c[1]:g})| <= {self.radius:g}"

    def contains(self, x: Any, tol: float = 1e-12) -> np.ndarray:
        x = np.asarray(x, float).reshape(-1, 2)
        u, w = x[:, 0] - self.center[0], x[:, 1] - self.center[1]
        return u * u + w * w <= (self.radius + tol) ** 2

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        self._sample_check(n)
        r = self.radius * np.sqrt(rng.uniform(size=n))
        t = rng.uniform(0.0, 2.0 * math.pi, size=n)
        return np.asarray(self.center) + np.stack([r * np.cos(t), r * np.sin(t)], 1)

    def project(self, x: Any) -> Any:
        if is_torch(x):
            import torch

            c = torch.as_tensor(self.center, dtype=x.dtype, device=x.device)
            d = x - c
            norm = torch.linalg.vector_norm(d, dim=-1, keepdim=True)
            outside = norm > self.radius
            safe = torch.where(outside, norm, torch.ones_like(norm))
            scale = torch.where(outside, self.radius / safe, torch.ones_like(norm))
            return c + d * scale
        x = np.asarray(x, float)
        c = np.asarray(self.center)
        d = x - c
        norm = np.linalg.norm(d, axis=-1, keepdims=True)
        scale = np.where(norm > self.radius, self.radius / np.maximum(norm, 1e-300), 1.0)
        return c + d * scale

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        c = np.asarray(self.center)
        return c - self.radius, c + self.radius

    def constraints_sx(self, x: ca.SX) -> list[tuple[ca.SX, float, float]]:
        d0, d1 = x[0] - self.center[0], x[1] - self.center[1]
        return [(d0 * d0 + d1 * d1, -ca.inf, self.radius**2)]


@dataclass(frozen=True)
class Product(Domain):
    """Cartesian product of domains, coordinates concatenated in order."""

    factors: tuple[Domain, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if len(self.factors) < 1:
            raise InputError("Product needs at least one factor")

    @property
    def dim(self) -> int:  # type: ignore[override]
        return sum(f.dim for f in self.factors)

    @property
    def is_box(self) -> bool:
        return all(f.is_box for f in self.factors)

    @property
    def names(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(n for f in self.factors for n in f.names)

    def describe(self) -> str:
        return " x ".join(f.describe() for f in self.factors)

    def _slices(self) -> list[slice]:
        out, k = [], 0
        for f in self.factors:
            out.append(slice(k, k + f.dim))
            k += f.dim
        return out

    def contains(self, x: Any, tol: float = 1e-12) -> np.ndarray:
        x = np.asarray(x, float).reshape(-1, self.dim)
        ok = np.ones(x.shape[0], bool)
        for f, s in zip(self.factors, self._slices()):
            ok &= f.contains(x[:, s], tol=tol)
        return ok

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        self._sample_check(n)
        return np.concatenate([f.sample(n, rng) for f in self.factors], axis=1)

    def project(self, x: Any) -> Any:
        parts = [f.project(x[..., s]) for f, s in zip(self.factors, self._slices())]
        if is_torch(x):
            import torch

            return torch.cat(parts, -1)
        return np.concatenate(parts, -1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = zip(*(f.bounds() for f in self.factors))
        return np.concatenate(lo), np.concatenate(hi)

    def constraints_sx(self, x: ca.SX) -> list[tuple[ca.SX, float, float]]:
        out = []
        for f, s in zip(self.factors, self._slices()):
            out.extend(f.constraints_sx(x[s.start : s.stop]))
        return out
