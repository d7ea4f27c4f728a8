"""The toolkit's one loader of a user's Python modules (``--metric-module``, the recorded
``module:qualname`` of a user metric in a run's config).

`import_user_module` imports a dotted module name or a ``.py`` file and turns every
way that can fail into one [`InputError`][finsler.errors.InputError] line naming the option and
the cause: a missing file or folder, a name that is not a module name (``..``, ``a/b``),
a syntax error, NUL bytes, an exception raised (or ``sys.exit`` called) while the module
runs. It never writes: no ``__pycache__/`` is left beside the user's file, also not by the
worker processes that import the module again (``PYTHONDONTWRITEBYTECODE`` is set for
them once a user file was loaded).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from types import ModuleType

from finsler.errors import InputError, short

__all__ = ["import_user_module"]


def _why(err: BaseException) -> str:
    """One short line saying what an import raised."""
    if isinstance(err, SyntaxError) and err.lineno:
        return f"syntax error at line {err.lineno}: {short(err.msg or '', 60)}"
    if isinstance(err, SystemExit):
        return f"the module called sys.exit({short(repr(err.code), 20)})"
    text = str(err).strip().splitlines()[0] if str(err).strip() else ""
    return f"{type(err).__name__}" + (f": {short(text, 80)}" if text else "")


def _no_bytecode() -> None:
    """No ``__pycache__`` beside a user's file, here and in the processes started later."""
    sys.dont_write_bytecode = True
    os.environ["PYTHONDONTWRITEBYTECODE"] = "1"


def _module_name(item: str, what: str) -> tuple[str, Path | None]:
    """The importable name of ``item`` and its file (None for a dotted name), checked."""
    looks_like_file = item.endswith(".py") or "/" in item or os.sep in item \
        or item in (".", "..") or item.startswith("~")
    if not looks_like_file:
        parts = item.split(".")
        if not item or not all(p.isidentifier() for p in parts):
            raise InputError(f"{what} {short(item)!r} is neither a module name (dotted "
                             "identifiers) nor a FILE.py")
        return item, None
    path = Path(item).expanduser()
    try:
        path = path.resolve()
        is_dir, is_file = path.is_dir(), path.is_file()
    except (OSError, RuntimeError, ValueError) as err:
        raise InputError(f"{what} {short(item)!r} cannot be read: {short(str(err), 60)}"
                         ) from err
    if is_dir:
        raise InputError(f"{what} {short(item)!r} is a folder; give a FILE.py or a module name")
    if not is_file:
        raise InputError(f"{what}: file {short(item)!r} does not exist")
    if path.suffix != ".py":
        raise InputError(f"{what} {short(item)!r} is not a .py file")
    if not path.stem.isidentifier():
        raise InputError(f"{what}: {short(path.name)} is not a valid module name (letters, "
                         "digits and _ only, not starting with a digit)")
    if not os.access(path, os.R_OK):
        raise InputError(f"{what} {short(item)!r} cannot be read: permission denied")
    return path.stem, path


def import_user_module(item: str, what: str = "--metric-module") -> ModuleType:
    """Import ``item``: a dotted module name, or a ``.py`` file (its folder is put first on
    ``sys.path`` and it is imported by its stem, so that the recorded ``module:qualname``
    of its metrics imports again, also in worker processes). Any failure is an
    `InputError` of one line starting with ``what``."""
    if not isinstance(item, str):
        raise InputError(f"{what} must be a module name or a FILE.py, got "
                         f"{type(item).__name__}")
    name, path = _module_name(item, what)
    if path is not None:
        loaded = sys.modules.get(name)
        if loaded is not None:
            where = getattr(loaded, "__file__", None)
            if where is None or Path(where).resolve() != path:
                raise InputError(f"{what}: a different module {name!r} is already imported "
                                 f"({short(str(where))}); rename {short(path.name)}")
        _no_bytecode()
        folder = str(path.parent)
        if folder not in sys.path:
            sys.path.insert(0, folder)
    try:
        return importlib.import_module(name)
    except KeyboardInterrupt:
        raise
    except BaseException as err:  # a user's module may raise anything, even SystemExit
        sys.modules.pop(name, None)
        raise InputError(f"{what} {short(item)!r}: cannot import it ({_why(err)})") from err
