"""The 2-D certificate: a piecewise-quadratic potential on a refined Delaunay mesh,
the best one an LP finds (`certificate`: the refinement loop; `bounds`: values of F,
enclosures of its second derivatives and the rows; `mesh`, `lp`, `repair`, `reach`)."""
