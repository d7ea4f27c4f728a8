"""The toolkit's infrastructure, below the geometry: process pools (:mod:`.pool`), Ray
clusters (:mod:`.cluster`), atomic files and run-file checks (:mod:`.files`), loading
users' modules (:mod:`.modules`), memory and size limits (:mod:`.limits`) and lazy public
names for packages (:mod:`.lazy`).

It lives in ``finsler`` because every package (``solvers``, ``learn``, ``validation``)
uses it and ``finsler`` is the ground floor of the one-way house; as a subpackage it keeps
``finsler/`` itself reading as geometry (metrics, domains, hooks, lowering, intervals,
kinematics, statuses). It imports nothing of the geometry but :mod:`finsler.errors`.

The old paths (``finsler.pool``, ``finsler.files``, ...) still import, with a
``DeprecationWarning`` (:mod:`finsler.infra.moved`).
"""
