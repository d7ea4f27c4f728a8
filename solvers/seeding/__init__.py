"""Global seeding: the plans that choose the initial curves (`plans`), the curves
themselves, and the routes of graphs over the domain (`graph`: lattices and roadmaps;
`field`: a shortest-path field over a lattice whose edges the metric chooses)."""
