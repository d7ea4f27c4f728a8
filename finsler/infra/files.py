"""The toolkit's one writer of output files, the check of an output path, and the one
reader of the files a user hands in (``.npy`` arrays, JSON and text files).

Every file the toolkit writes (run directories, policies, solver results and their
resumable parts, reports, figures) goes through `atomic_write_bytes`: the data is
written to a temporary file in the target's folder and renamed over the target, so a
reader sees the old file or the new one, never half of one. A symbolic link is written
THROUGH (its target gets the new content; the link stays a link); an existing target that
is not a regular file (a directory, a device such as ``/dev/full`` or ``/dev/stdout``, a
pipe, a socket) is refused, never replaced. A write that fails (a full disk, no
permission) leaves the target as it was, removes the temporary file and raises
`OutputError` naming the path.

`check_output_path` runs the same checks without writing, so that commands can
refuse a bad output path before they do any work: every name of the path fits the file
system (`NAME_MAX` bytes a name, `PATH_MAX` in all), and the folder it goes to
takes a new file (a probe file is created and removed at once: a read-only file system or a
folder without write permission is refused, also for root). `check_output_dir` does
the same for an output folder (``report``, ``sweep``, ``train``), without creating it.

Reading: `read_npy` checks a ``.npy`` file's header (dtype, shape, and the memory the
array needs, `finsler.infra.limits.check_memory`) before it allocates anything, so a file
whose header claims 10**12 rows is a clear error, not a machine out of memory;
`read_text` reads a text file of bounded size. Both raise `InputError` naming
the file and the problem (missing, a folder, unreadable, too large, not the format).
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from finsler.errors import InputError, short
from finsler.infra.limits import check_memory

__all__ = [
    "NAME_MAX",
    "PATH_MAX",
    "OutputError",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_input_dir",
    "check_input_file",
    "check_output_dir",
    "check_output_path",
    "check_path_text",
    "made_folders",
    "read_npy",
    "read_text",
]

#: Longest file or folder name (bytes, UTF-8) of the usual file systems (ext4, xfs, btrfs).
NAME_MAX = 255
#: Longest path (bytes) the operating system accepts.
PATH_MAX = 4096


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


def _check_names(path: str | os.PathLike[str], what: str) -> None:
    """Every name of ``path`` fits the file system, the whole path the OS, no NUL byte."""
    text = os.fsdecode(path)
    if "\x00" in text:
        raise OutputError(f"{what} {short(text)!r} contains a NUL byte")
    try:
        raw = os.fsencode(text)
    except UnicodeError as err:
        raise OutputError(f"{what} {short(text)!r} cannot be encoded as a file name") from err
    if len(raw) > PATH_MAX:
        raise OutputError(f"{what} {short(text)!r} is too long ({len(raw)} bytes, the "
                          f"limit is {PATH_MAX})")
    for part in Path(text).parts:
        n = len(os.fsencode(part))
        if n > NAME_MAX:
            raise OutputError(f"{what} {short(text)!r}: the name {short(part, 24)!r} is "
                              f"{n} bytes long, the limit is {NAME_MAX}")


def check_path_text(path: Any, what: str) -> Path:
    """``path`` (a ``str`` or ``os.PathLike``, not bytes) as a ``Path`` whose names fit the
    file system, else `InputError` naming ``what`` and the (shortened) value: the
    check of a path given to read, before the file system is asked about it."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise InputError(f"{what} must be a str or a path, got {type(path).__name__} "
                         f"{short(repr(path), 80)}")
    try:
        _check_names(path, what)
    except OutputError as err:
        raise InputError(str(err)) from None
    return Path(path)


def _existing_folder(folder: Path, path: str | os.PathLike[str], what: str) -> Path:
    """The nearest existing ancestor of ``folder`` (itself included), checked to be a
    folder that takes new files (a probe file is created and removed)."""
    for anc in (folder, *folder.parents):
        try:
            st = os.stat(anc)
        except (FileNotFoundError, NotADirectoryError):  # look further up
            continue
        except OSError as err:
            raise OutputError(f"{what} {short(str(path))!r}: {short(str(anc))!r} cannot be "
                              f"checked: {err.strerror}") from err
        if not stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{what} {short(str(path))!r}: {short(str(anc))!r} is a file, "
                              "not a folder")
        try:
            fd, probe = tempfile.mkstemp(prefix=".write-probe.", dir=anc)
        except OSError as err:
            raise OutputError(f"{what} {short(str(path))!r}: cannot write in folder "
                              f"{short(str(anc))!r}: {err.strerror}") from err
        os.close(fd)
        os.unlink(probe)
        return anc
    raise OutputError(f"{what} {short(str(path))!r}: no existing folder on its path")


def check_output_dir(path: str | os.PathLike[str], what: str = "output folder") -> Path:
    """The output folder ``path``, checked without creating it: its names fit, it is a
    folder if it exists, and it (or, if absent, its nearest existing ancestor) takes new
    files. Returns ``Path(path)``; raises `OutputError` naming the problem."""
    if os.fspath(path) == "":
        raise OutputError(f"{what} '' is not a folder name")
    _check_names(path, what)
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{what} {short(str(path))!r} exists and is not a folder")
    _existing_folder(p, path, what)
    return p


@contextlib.contextmanager
def made_folders(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Run a job that writes into the folder ``path`` (created by the job, parents and
    all): if the job fails, every folder of ``path`` that did not exist before and is
    still empty is removed, so a failed command leaves nothing behind."""
    p = Path(path)
    new: list[Path] = []
    q = p
    while not q.exists() and q != q.parent:
        new.append(q)
        q = q.parent
    try:
        yield p
    except BaseException:
        for folder in new:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                break  # not empty (the job wrote something) or gone
        raise


def check_output_path(path: str | os.PathLike[str], what: str = "output file",
                      create_parent: bool = True) -> Path:
    """The path to write ``what`` to, checked: its names fit the file system; a symbolic
    link resolves to its target; an existing target must be a regular file; its folder
    must exist or (``create_parent``) be creatable, be a folder and take new files.
    Returns the resolved path; raises `OutputError` naming the problem."""
    p = Path(path)
    if os.fspath(path) == "" or p.name in ("", ".", ".."):
        raise OutputError(f"{what} {short(str(path))!r} is not a file name")
    _check_names(path, what)
    if p.is_symlink():
        target = Path(os.path.realpath(p))
        if not target.parent.is_dir():  # a dangling link never creates its target's folders
            raise OutputError(f"{what} {short(str(path))!r} is a symbolic link to "
                              f"{short(str(target))!r}, whose folder does not exist")
        p = target
    parent = p.parent
    _existing_folder(parent, path, what)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        st = None
    except OSError as err:
        raise OutputError(f"{what} {short(str(path))!r} cannot be checked: "
                          f"{err.strerror}") from err
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise OutputError(f"{what} {short(str(path))!r} exists and is "
                          f"{_describe(st.st_mode)}; refusing to replace it (give the path "
                          "of a regular file)")
    if not parent.is_dir():
        if not create_parent:
            raise OutputError(f"{what} {short(str(path))!r}: folder {short(str(parent))!r} "
                              "does not exist")
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"{what} {short(str(path))!r}: cannot create folder "
                              f"{short(str(parent))!r}: {err.strerror}") from err
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
        raise OutputError(f"cannot write {what} {short(str(path))!r}: {err.strerror}") from err
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
            raise OutputError(f"cannot write {what} {short(str(path))!r}: "
                              f"{err.strerror or short(str(err))}; "
                              "the previous file, if any, is unchanged") from err
        raise
    return target


def atomic_write_text(path: str | os.PathLike[str], text: str,
                      what: str = "output file") -> Path:
    """`atomic_write_bytes` of UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"), what)


# ----------------------------------------------------------------------------------------
# reading the files a user hands in
# ----------------------------------------------------------------------------------------
def check_input_dir(path: str | os.PathLike[str], what: str = "input folder") -> Path:
    """``path`` as an existing folder that can be read, else `InputError` naming
    the problem (missing, a file, no permission, a name too long)."""
    p, st = _stat_input(path, what)
    if not stat.S_ISDIR(st.st_mode):
        raise InputError(f"{what} {short(str(p))!r} is a file, not a folder")
    if not os.access(p, os.R_OK | os.X_OK):
        raise InputError(f"{what} {short(str(p))!r} cannot be read: permission denied")
    return p


def _stat_input(path: str | os.PathLike[str], what: str) -> tuple[Path, os.stat_result]:
    text = os.fspath(path)
    if text == "" or "\x00" in str(text):
        raise InputError(f"{what} {short(str(text))!r} is not a file name")
    p = Path(path)
    try:
        return p, os.stat(p)
    except FileNotFoundError:
        raise InputError(f"{what} {short(str(p))!r} does not exist") from None
    except OSError as err:
        raise InputError(f"{what} {short(str(p))!r} cannot be read: {err.strerror}") from err


def check_input_file(path: str | os.PathLike[str], what: str = "input file") -> Path:
    """``path`` as an existing regular file that can be opened, else `InputError`
    naming the problem (missing, a folder, a special file, no permission, bad name)."""
    p, st = _stat_input(path, what)
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{what} {short(str(p))!r} is a folder, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{what} {short(str(p))!r} is {_describe(st.st_mode)}, not a "
                         "regular file")
    if not os.access(p, os.R_OK):
        raise InputError(f"{what} {short(str(p))!r} cannot be read: permission denied")
    return p


def read_text(path: str | os.PathLike[str], what: str = "input file",
              max_bytes: int = 64 * 1024**2) -> str:
    """The UTF-8 text of a user's file of at most ``max_bytes`` bytes (checked before
    reading), else `InputError` naming the problem."""
    p = check_input_file(path, what)
    size = p.stat().st_size
    if size > max_bytes:
        raise InputError(f"{what} {short(str(p))!r} is {size / 1024**2:.3g} MiB, over the "
                         f"limit of {max_bytes / 1024**2:g} MiB")
    try:
        return p.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise InputError(f"{what} {short(str(p))!r} is not UTF-8 text (byte {err.start})"
                         ) from err
    except OSError as err:
        raise InputError(f"{what} {short(str(p))!r} cannot be read: {err.strerror}") from err


def read_npy(path: str | os.PathLike[str], what: str = "array file") -> Any:
    """The array of a ``.npy`` file, its header checked before any allocation: numeric
    dtype (no pickled objects), a shape whose array fits `MAX_BYTES`
    (`finsler.infra.limits.check_memory`) and a file long enough to hold it. Raises
    `InputError` naming the file and the problem."""
    import numpy as np

    p = check_input_file(path, what)
    name = short(str(p))
    try:
        with open(p, "rb") as f:
            try:
                version = np.lib.format.read_magic(f)
                if version == (1, 0):
                    shape, _fortran, dtype = np.lib.format.read_array_header_1_0(f)
                elif version in ((2, 0), (3, 0)):
                    shape, _fortran, dtype = np.lib.format.read_array_header_2_0(f)
                else:  # pragma: no cover - numpy accepts only these
                    raise ValueError(f"unknown .npy version {version}")
            except (ValueError, SyntaxError, TypeError, EOFError, UnicodeError) as err:
                raise InputError(
                    f"{what} {name} is not a readable .npy array (a text file renamed "
                    f".npy?): {short(str(err), 60)}; write it with numpy.save(path, array)"
                ) from err
            if dtype.hasobject or dtype.kind not in "fiub":
                raise InputError(f"{what} {name} must hold a numeric array, not dtype "
                                 f"{short(str(dtype), 40)} (pickled Python objects are never "
                                 "loaded)")
            need = check_memory(shape, f"{what} {name}", itemsize=max(dtype.itemsize, 1))
            have = p.stat().st_size - f.tell()
            if have < need:
                raise InputError(f"{what} {name} is truncated: its header announces shape "
                                 f"{tuple(shape)} ({need} bytes) but {max(have, 0)} bytes "
                                 "follow")
            f.seek(0)
            arr = np.load(f, allow_pickle=False)
    except InputError:
        raise
    except OSError as err:
        raise InputError(f"{what} {name} cannot be read: {err.strerror or err}") from err
    except ValueError as err:
        raise InputError(f"{what} {name} is not a readable .npy array: "
                         f"{short(str(err), 80)}") from err
    return arr

