"""Distance fields: ``d(source, .)`` on a whole 2-D or 3-D grid by a semi-Lagrangian
eikonal scheme (`solvers.fields.eikonal`), the result object with its error estimate,
interpolation and backtracked geodesics (`solvers.fields.field`), and distance
matrices (`solvers.fields.matrix`)."""

from solvers.fields.field import DistanceField, FieldGeodesic, distance_field
from solvers.fields.matrix import DistanceMatrix, distance_matrix

__all__ = ["DistanceField", "DistanceMatrix", "FieldGeodesic", "distance_field",
           "distance_matrix"]
