"""Lazy public names of a package (PEP 562), shared by ``finsler`` and ``solvers``: a name is
imported from its defining module on first use, so ``import solvers`` (and the command
line's ``--help``) does not pay for scipy.integrate, CasADi or IPOPT until they are used."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, table: Mapping[str, str], namespace: dict[str, Any],
                 public: list[str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package`` whose public names ``table`` maps to their
    defining modules; ``namespace`` is the package's ``globals()`` (a loaded name is cached
    there, so the next lookup is a plain attribute); ``public`` its ``__all__``. A name not
    in ``table`` is tried as a submodule (``package.name``), else AttributeError."""

    def __getattr__(name: str) -> Any:
        module = table.get(name)
        if module is None:  # a submodule reached as an attribute (``package.sub.X``)
            try:
                return importlib.import_module(f"{package}.{name}")
            except ModuleNotFoundError as err:
                if err.name != f"{package}.{name}":
                    raise
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(public))

    return __getattr__, __dir__
