"""The test metrics of ``tests/validation/testing/test_metric.py``: Base, NanOutside,
NegativeCone, Offset, Squared, Root, ConvexClaimed, Kinked, RandersClaimedReversible,
EuclidClaimedIrreversible, HiddenConvexity, OffNumpy, OffTorch, OffHessian, ZeroCone,
NanAndNegativeCones, HalfZero, Zero, SlightlySquared, Drift, TinyAsymmetric, KinkedV,
NanOutsideOff, Shaped, RootX, SquaredX, ShortBy, SmallScaleOff, LargeScaleOff,
InfOnAxis, ZeroOnAxis, ScaledEuclid, OffAbs, OffHessianAbs, TinyKinkV, C1KinkV,
KinkOffCentre, NanBeyond095Off, OffNumpyShaped, DiagonalKink."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from finsler import Box, Disk, Matsumoto, Metric, Randers, Task


class Base(Metric):
    task = Task(depth=3, eps=0.5)
    reversible = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.sqrt(ca.dot(v, v))


class NanOutside(Base):
    """F = |v| on the unit disk, NaN for |x| > 0.9."""

    name = "nan-outside-test"
    domain = property(lambda self: Disk(radius=1.0))

    def F_sx(self, x, v):
        return ca.if_else(ca.dot(x, x) > 0.81, float("nan"), ca.sqrt(ca.dot(v, v)))


class NegativeCone(Base):
    """F = -|v| in a thin cone of directions around (cos 1, sin 1), |v| elsewhere."""

    name = "negative-cone-test"
    smooth = False

    def F_sx(self, x, v):
        n = ca.sqrt(ca.dot(v, v))
        c = (math.cos(1.0) * v[0] + math.sin(1.0) * v[1]) / n
        return ca.if_else(c > 0.99, -n, n)


class Offset(Base):
    """F(x, 0) = 1e-3."""

    name = "offset-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) + 1e-3


class Squared(Base):
    name = "squared-test"

    def F_sx(self, x, v):
        return ca.dot(v, v)


class Root(Base):
    """F = sqrt|v|: subadditive (concave) but the midpoint form fails."""

    name = "root-test"

    def F_sx(self, x, v):
        return ca.dot(v, v) ** 0.25


class ConvexClaimed(Matsumoto):
    """Matsumoto declared convex everywhere (it is not beyond |x| = RC)."""

    name = "convex-claimed-test"
    convex_everywhere = True


class Kinked(Base):
    """F = |v| (1 + 0.3 |x0|) declared smooth."""

    name = "kinked-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) * (1.0 + 0.3 * ca.fabs(x[0]))


class RandersClaimedReversible(Randers):
    name = "randers-reversible-test"
    reversible = True


class EuclidClaimedIrreversible(Base):
    name = "euclid-irreversible-test"
    reversible = False


class HiddenConvexity(ConvexClaimed):
    """The 7-direction test (the search's) sees a convex F; the map's 32 see the real one."""

    name = "hidden-convexity-test"

    def convexity(self, x, n_directions=64, seed=0):
        lam = super().convexity(x, n_directions=n_directions, seed=seed)
        return np.abs(lam) + 1e-3 if n_directions == 7 else lam


class OffNumpy(Randers):
    name = "off-numpy-test"

    def F(self, x, v, check=None):
        out = super().F(x, v, check=check)
        return out * (1 + 1e-9) if isinstance(out, (np.ndarray, float)) else out


class OffTorch(Randers):
    name = "off-torch-test"

    def F(self, x, v, check=None):
        out = super().F(x, v, check=check)
        return out if isinstance(out, (np.ndarray, float)) else out * (1 + 1e-9)


class OffHessian(Randers):
    name = "off-hessian-test"

    def lowered_hessian(self, x, v):
        (h,) = super().lowered_hessian(x, v)
        h = np.array(h, float)
        h.reshape(-1)[1] += 1e-6
        return (h,)


# ----------------------------------------------------------------------------------------
# after the first testing_metric run (its survivors)
# ----------------------------------------------------------------------------------------
class ZeroCone(NegativeCone):
    """F = 0 in a thin cone of directions, |v| elsewhere (zero, not negative)."""

    name = "zero-cone-test"

    def F_sx(self, x, v):
        n = ca.sqrt(ca.dot(v, v))
        c = (math.cos(1.0) * v[0] + math.sin(1.0) * v[1]) / n
        return ca.if_else(c > 0.99, 0.0 * n, n)


class NanAndNegativeCones(NegativeCone):
    """F NaN in one thin cone, -|v| in the opposite one: the NaN is the worse."""

    name = "nan-negative-cones-test"

    def F_sx(self, x, v):
        n = ca.sqrt(ca.dot(v, v))
        c = (math.cos(1.0) * v[0] + math.sin(1.0) * v[1]) / n
        return ca.if_else(c > 0.99, float("nan"), ca.if_else(c < -0.99, -n, n))


class HalfZero(Base):
    """F = |v| for x0 >= 0, 0 for x0 < 0 (finite, not positive)."""

    name = "half-zero-test"
    smooth = False

    def F_sx(self, x, v):
        return ca.if_else(x[0] < 0, 0.0, ca.sqrt(ca.dot(v, v)))


class Zero(Base):
    name = "zero-test"

    def F_sx(self, x, v):
        return 0.0 * ca.sqrt(ca.dot(v, v))


class SlightlySquared(Base):
    """F = |v| + 1e-6 |v|^2: homogeneity off by 1e-6 relative (absolute far below 1)."""

    name = "slightly-squared-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) + 1e-6 * ca.dot(v, v)


class Drift(Base):
    """F = |v| + 0.1 x0 v0 declared reversible: asymmetric wherever x0 v0 != 0."""

    name = "drift-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) + 0.1 * x[0] * v[0]


class TinyAsymmetric(Base):
    """F = 1e-3 (|v| + 1e-12 v0): relatively asymmetric by ~2e-12 > 1e-13, absolutely by
    ~1e-15 (so a tolerance rtol / F would pass it)."""

    name = "tiny-asymmetric-test"

    def F_sx(self, x, v):
        return 1e-3 * (ca.sqrt(ca.dot(v, v)) + 1e-12 * v[0])


class KinkedV(Base):
    """F = |v| + 0.2 |v0| declared smooth: a kink at v0 = 0, where hypothesis looks first."""

    name = "kinked-v-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) + 0.2 * ca.fabs(v[0])


class NanOutsideOff(Base):
    """F = |v| on the disk of radius 1 about (2, -1), NaN beyond 0.9 from its centre."""

    name = "nan-outside-off-test"
    domain = property(lambda self: Disk(radius=1.0, center=(2.0, -1.0)))

    def F_sx(self, x, v):
        d = x - ca.DM([2.0, -1.0])
        return ca.if_else(ca.dot(d, d) > 0.81, float("nan"), ca.sqrt(ca.dot(v, v)))


class Shaped(Base):
    """Depends on x (so a counterexample's x can be told from its v): the factor
    1 + x0^2 + 2 x1^2 times g(|v|)."""

    def factor(self, x):
        return 1.0 + x[0] ** 2 + 2.0 * x[1] ** 2


class RootX(Shaped):
    """(1 + x0^2 + 2 x1^2) sqrt|v|: the midpoint form of subadditivity fails."""

    name = "root-x-test"

    def F_sx(self, x, v):
        return self.factor(x) * ca.dot(v, v) ** 0.25


class SquaredX(Shaped):
    name = "squared-x-test"

    def F_sx(self, x, v):
        return self.factor(x) * ca.dot(v, v)


class ShortBy(Base):
    """|v| - delta: F(x, v + w) - F(x, v) - F(x, w) = delta for parallel v, w."""

    def __init__(self, delta):
        self.delta = delta
        self.name = f"short-by-{delta:g}-test"
        super().__init__()

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) - self.delta


class SmallScaleOff(Base):
    """|v| for |v| >= 0.5, larger below: homogeneous only for scales that stay above 0.5."""

    name = "small-scale-off-test"

    def F_sx(self, x, v):
        n = ca.sqrt(ca.dot(v, v))
        return n * (1.0 + 0.5 * ca.fmax(0.0, 0.5 - n))


class LargeScaleOff(Base):
    """|v| up to |v| = 100.5, larger beyond."""

    name = "large-scale-off-test"

    def F_sx(self, x, v):
        n = ca.sqrt(ca.dot(v, v))
        return n * (1.0 + ca.fmax(0.0, n - 100.5))


class InfOnAxis(Base):
    name = "inf-on-axis-test"

    def F_sx(self, x, v):
        return ca.if_else(v[0] == 0, float("inf"), ca.sqrt(ca.dot(v, v)))


class ZeroOnAxis(Base):
    name = "zero-on-axis-test"

    def F_sx(self, x, v):
        return ca.if_else(v[0] == 0, 0.0, ca.sqrt(ca.dot(v, v)))


class ScaledEuclid(Base):
    def __init__(self, k):
        self.k = k
        self.name = f"scaled-euclid-{k:g}-test"
        super().__init__()

    def F_sx(self, x, v):
        return self.k * ca.sqrt(ca.dot(v, v))


class OffAbs(ScaledEuclid):
    """numpy F = symbolic F + off (torch untouched)."""

    def __init__(self, k, off, rel=False):
        self.off, self.rel = off, rel
        super().__init__(k)
        self.name += f"-off-{off:g}-{rel}"

    def F(self, x, v, check=None):
        out = super().F(x, v, check=check)
        if isinstance(out, (np.ndarray, float)):
            return out * (1.0 + self.off) if self.rel else out + self.off
        return out


class OffHessianAbs(ScaledEuclid):
    def lowered_hessian(self, x, v):
        (h,) = super().lowered_hessian(x, v)
        return (np.array(h, float) + 1e-9,)


class TinyKinkV(Base):
    """|v| + 2e-6 |v0| declared smooth: at v0 = 0 the search's error is ~1e-3 relative,
    far above its 1e-6 but under the sweep's 1e-3 at its larger step."""

    name = "tiny-kink-v-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) + 2e-6 * ca.fabs(v[0])


class C1KinkV(Base):
    """F^2 = |v|^2 + 0.3 max(0, v0)^2: C^1, its second derivative jumps at v0 = 0 (the
    second difference's error there does not shrink with the step)."""

    name = "c1-kink-v-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v) + 0.3 * ca.fmax(0.0, v[0]) ** 2)


class KinkOffCentre(Base):
    """|v| (1 + 0.3 |x0 - 0.3127|) declared smooth: the search rarely draws x0 within its
    step of the kink; the sweep does."""

    name = "kink-off-centre-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) * (1.0 + 0.3 * ca.fabs(x[0] - 0.3127))


class NanBeyond095Off(Base):
    """|v| on the disk of radius 1 about (2, -1), NaN beyond 0.95 of it: the smoothness
    checks stay within 0.9 of the centre (plus their steps)."""

    name = "nan-beyond-095-off-test"
    domain = property(lambda self: Disk(radius=1.0, center=(2.0, -1.0)))

    def F_sx(self, x, v):
        d = x - ca.DM([2.0, -1.0])
        return ca.if_else(ca.dot(d, d) > 0.9025, float("nan"), ca.sqrt(ca.dot(v, v)))


class OffNumpyShaped(Shaped):
    """(1 + x0^2 + 2 x1^2) |v|, its numpy form off by 1e-9 relative (torch exact)."""

    name = "off-numpy-shaped-test"

    def F_sx(self, x, v):
        return self.factor(x) * ca.sqrt(ca.dot(v, v))

    def F(self, x, v, check=None):
        out = super().F(x, v, check=check)
        return out * (1 + 1e-9) if isinstance(out, (np.ndarray, float)) else out


class DiagonalKink(Base):
    """|v| (1 + 0.3 |x0 - x1|) declared smooth: a kink along the diagonal, invisible to a
    step whose x part moves both coordinates alike."""

    name = "diagonal-kink-test"

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v)) * (1.0 + 0.3 * ca.fabs(x[0] - x[1]))
