"""One place that bounds memory before allocating: every array whose size a user chooses
(quadrature order, tree depth, number of pairs) is checked here first, so that an
impossible request is a clear error with the figure, not a machine out of memory."""

from __future__ import annotations

import math
from collections.abc import Sequence

from finsler.errors import InputError

__all__ = ["MAX_BYTES", "check_memory", "rows_that_fit"]

#: Largest working set (bytes) a single request may need: 4 GiB.
MAX_BYTES = 4 * 1024**3


def check_memory(shape: Sequence[int], what: str, hint: str = "", itemsize: int = 8,
                 copies: int = 1) -> int:
    """Raise `InputError` if ``copies`` arrays of ``shape`` and ``itemsize`` bytes
    per element would exceed `MAX_BYTES`; returns the bytes needed otherwise."""
    need = math.prod(int(s) for s in shape) * itemsize * copies
    if need > MAX_BYTES:
        raise InputError(f"{what} would need about {need / 1024**3:.3g} GiB (arrays of shape "
                         f"{tuple(int(s) for s in shape)}), over the limit of "
                         f"{MAX_BYTES / 1024**3:g} GiB" + (f"; {hint}" if hint else ""))
    return need


def rows_that_fit(row_shape: Sequence[int], what: str, hint: str = "", itemsize: int = 8,
                  copies: int = 1) -> int:
    """How many independent rows of ``row_shape`` (``copies`` arrays of ``itemsize`` bytes
    per element) fit `MAX_BYTES` at once, at least 1: the part size of work that is
    split into rows. Raises `InputError` (`check_memory`) if one row does not
    fit."""
    need = check_memory((1, *row_shape), what, hint, itemsize, copies)
    return max(1, MAX_BYTES // max(need, 1))
