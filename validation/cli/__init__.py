"""The ``geodesics`` command line (typer), a package of its own on top of the library.

One module per command group (``solve``, ``train`` (train and evaluate), ``report``, ``plot``,
``sweep``, ``expmap``, ``certify``, ``check``), the options and input parsing they share in
`validation.cli.common`, and the root application with its console-script entry point
in `validation.cli.entry`. Every command calls public functions of ``finsler``,
``solvers``, ``learn`` or ``validation``; nothing is reachable only from here.

It lives inside ``validation/`` because the design card fixes the top-level packages
(``finsler``, ``solvers``, ``learn``, ``validation``); nothing below it imports it.
"""

from validation.cli.entry import app, main

__all__ = ["app", "main"]
