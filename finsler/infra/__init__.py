"""The toolkit's infrastructure, below the geometry: process pools (`.pool`), Ray
clusters (`.cluster`), atomic files and run-file checks (`.files`), loading
users' modules (`.modules`), memory and size limits (`.limits`) and lazy public
names for packages (`.lazy`).

It lives in ``finsler`` because every package (``solvers``, ``learn``, ``validation``)
uses it and ``finsler`` is the ground floor of the one-way house; as a subpackage it keeps
``finsler/`` itself reading as geometry (metrics, domains, hooks, lowering, intervals,
kinematics, statuses). It imports nothing of the geometry but `finsler.errors`.
"""
