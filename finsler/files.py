"""The toolkit's one writer of output files, and the check of an output path.

Every file the toolkit writes (run directories, policies, solver results and their
resumable parts, reports, figures) goes through :func:`atomic_write_bytes`: the data is
written to a temporary file in the target's folder and renamed over the target, so a
reader sees the old file or the new one, never half of one. A symbolic link is written
THROUGH (its target gets the new content; the link stays a link); an existing target that
is not a regular file (a directory, a device such as ``/dev/full`` or ``/dev/stdout``, a
pipe, a socket) is refused, never replaced. A write that fails (a full disk, no
permission) leaves the target as it was, removes the temporary file and raises
:class:`OutputError` naming the path.

:func:`check_output_path` runs the same checks without writing, so that commands can
refuse a bad output path before they do any work.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from finsler.errors import InputError

__all__ = ["OutputError", "atomic_write_bytes", "atomic_write_text", "check_output_path"]


class OutputError(InputError):
    """An output file cannot be written: bad path, special file, or a failed write."""


def _describe(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a pipe"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_output_path(path: str | os.PathLike[str], what: str = "output file",
                      create_parent: bool = True) -> Path:
    """The path to write ``what`` to, checked: a symbolic link resolves to its target; an
    existing target must be a regular file; its folder must exist or (``create_parent``)
    be creatable, and be a folder. Returns the resolved path; raises :class:`OutputError`
    naming the problem."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputError(f"{what} {str(path)!r} is not a file name")
    if p.is_symlink():
        p = Path(os.path.realpath(p))
    parent = p.parent
    for anc in (parent, *parent.parents):
        if os.path.lexists(anc):
            if not anc.is_dir():
                raise OutputError(f"{what} {str(path)!r}: {str(anc)!r} is a file, not a "
                                  "folder")
            break
    try:
        st = os.stat(p)
    except FileNotFoundError:
        st = None
    except OSError as err:
        raise OutputError(f"{what} {str(path)!r} cannot be checked: {err.strerror}") from err
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise OutputError(f"{what} {str(path)!r} exists and is {_describe(st.st_mode)}; "
                          "refusing to replace it (give the path of a regular file)")
    if not parent.is_dir():
        if not create_parent:
            raise OutputError(f"{what} {str(path)!r}: folder {str(parent)!r} does not exist")
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"{what} {str(path)!r}: cannot create folder {str(parent)!r}: "
                              f"{err.strerror}") from err
    return p


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes,
                       what: str = "output file") -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); returns the path
    written (a symbolic link's target)."""
    target = check_output_path(path, what)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp",
                                   dir=target.parent)
    except OSError as err:
        raise OutputError(f"cannot write {what} {str(path)!r}: {err.strerror}") from err
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; results and policies are shared
        os.replace(tmp, target)
    except BaseException as err:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise OutputError(f"cannot write {what} {str(path)!r}: {err.strerror or err}; "
                              "the previous file, if any, is unchanged") from err
        raise
    return target


def atomic_write_text(path: str | os.PathLike[str], text: str,
                      what: str = "output file") -> Path:
    """:func:`atomic_write_bytes` of UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), what)
