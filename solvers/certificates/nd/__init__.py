"""The certificate in 3 and more dimensions: a potential on a graded point cloud
verified cell by cell with interval arithmetic (`certificate`; `parts`: directions,
cells, enclosures, the LP; `p2`: quadratic potentials)."""
