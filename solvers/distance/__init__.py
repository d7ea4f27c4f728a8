"""Distance fields: ``d(source, .)`` on a whole 2-D or 3-D grid by a semi-Lagrangian
eikonal scheme (`solvers.distance.eikonal`), the result object with its error estimate,
interpolation and backtracked geodesics (`solvers.distance.field`), and distance
matrices (`solvers.distance.matrix`)."""

from solvers.distance.field import DistanceField, FieldGeodesic, distance_field
from solvers.distance.matrix import DistanceMatrix, distance_matrix

__all__ = ["DistanceField", "DistanceMatrix", "FieldGeodesic", "distance_field",
           "distance_matrix"]
