"""Certified intervals ``lower <= d(start, goal) <= upper``: one entry
(`solvers.certify`, in `dispatch`) that picks the certificate by what the metric
provides: `plane` (2-D, a P2 potential on a refined mesh, an LP), `conformal` (a
conformal factor in any dimension, potentials on a grid along the chord), `nd` (3-D and
up, potentials verified cell by cell). `domain` holds the domain's constraints over
boxes, which `conformal` and `nd` share."""
