"""Importing a user's module by name or from a ``.py`` file (``--metric-module``,
``--method-module``): what registers a user's metric or learning method."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from finsler.errors import InputError

__all__ = ["import_module_or_file"]


def import_module_or_file(item: str, option: str = "--metric-module") -> str:
    """Import ``item``: a dotted module name, or a ``.py`` file (its folder is put first on
    ``sys.path`` and it is imported by its stem, so that the name a run records, e.g. a
    metric's ``module:qualname``, imports again, also in worker processes). Returns the
    module's name; :class:`InputError` naming ``option`` if it cannot be imported."""
    name = str(item)
    if name.endswith(".py") or "/" in name:
        path = Path(name).expanduser().resolve()
        if not path.is_file():
            raise InputError(f"{option}: file {item} does not exist")
        if not path.stem.isidentifier():
            raise InputError(f"{option}: {path.name} is not a valid module name")
        folder = str(path.parent)
        if folder not in sys.path:
            sys.path.insert(0, folder)
        name = path.stem
        loaded = sys.modules.get(name)
        if loaded is not None and Path(getattr(loaded, "__file__", "") or "").resolve() \
                != path:
            raise InputError(f"{option}: a different module {name!r} is already imported "
                             f"({getattr(loaded, '__file__', None)}); rename {path.name}")
    try:
        importlib.import_module(name)
    except ImportError as err:
        raise InputError(f"{option}: cannot import {item!r}: {err}") from err
    return name
