"""Array backends of the batched Newton solver: the few array operations it needs, on
numpy (float64, CPU) and on torch tensors on any device.

`backend_for` maps a device (``None``: numpy; ``"cpu"``, ``"cuda"``, a
``torch.device``: torch float64 there) to a backend object; the solver
(`solvers.newton.energy`) and the block-tridiagonal linear algebra
(`solvers.newton.block_tridiagonal`) call only its methods (``asarray``, ``zeros``,
``where``, ``cat``, ...) and the lowering it carries (`finsler.lowering`), so one
code runs on both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from finsler.errors import InputError, short

__all__ = ["backend_for"]


class _Numpy:
    name = "numpy"

    def __init__(self) -> None:
        from finsler.lowering import _NUMPY

        self.lowering = _NUMPY

    @staticmethod
    def asarray(a: Any) -> np.ndarray:
        return np.array(a, dtype=np.float64)  # a copy: never the caller's array

    @staticmethod
    def to_numpy(a: Any) -> np.ndarray:
        return np.asarray(a)

    @staticmethod
    def zeros(shape: tuple[int, ...]) -> np.ndarray:
        return np.zeros(shape)

    @staticmethod
    def full(shape: tuple[int, ...], value: float) -> np.ndarray:
        return np.full(shape, value)

    @staticmethod
    def index(a: Any) -> np.ndarray:
        return np.asarray(a, dtype=np.int64)

    @staticmethod
    def mask(a: Any) -> np.ndarray:
        return np.asarray(a, dtype=bool)

    @staticmethod
    def cat(arrays: list[Any], axis: int) -> np.ndarray:
        return np.concatenate(arrays, axis=axis)

    @staticmethod
    def contiguous(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a)

    @staticmethod
    def stack_cols(cols: list[Any]) -> np.ndarray:
        return np.stack(cols, 1)

    @staticmethod
    def stack(arrays: list[Any], axis: int) -> np.ndarray:
        return np.stack(arrays, axis)

    @staticmethod
    def clip(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
        return np.clip(a, lo, hi)

    sqrt = staticmethod(np.sqrt)
    abs = staticmethod(np.abs)
    where = staticmethod(np.where)
    isfinite = staticmethod(np.isfinite)
    maximum = staticmethod(np.maximum)


class _Torch:
    name = "torch"

    def __init__(self, device: Any) -> None:
        import torch

        from finsler.lowering import _torch_backend

        self.torch = torch
        self.device = torch.device(device)
        self.lowering = _torch_backend()

    def asarray(self, a: Any) -> Any:
        t = self.torch
        if isinstance(a, t.Tensor):
            return a.detach().to(device=self.device, dtype=t.float64).clone()
        return t.tensor(np.asarray(a, dtype=np.float64), device=self.device)

    @staticmethod
    def to_numpy(a: Any) -> np.ndarray:
        return a.detach().cpu().numpy() if hasattr(a, "detach") else np.asarray(a)

    def zeros(self, shape: tuple[int, ...]) -> Any:
        return self.torch.zeros(shape, dtype=self.torch.float64, device=self.device)

    def full(self, shape: tuple[int, ...], value: float) -> Any:
        return self.torch.full(shape, float(value), dtype=self.torch.float64,
                               device=self.device)

    def index(self, a: Any) -> Any:
        return self.torch.as_tensor(np.asarray(a, dtype=np.int64), device=self.device)

    def mask(self, a: Any) -> Any:
        return self.torch.as_tensor(np.asarray(a, dtype=bool), device=self.device)

    def cat(self, arrays: list[Any], axis: int) -> Any:
        return self.torch.cat(arrays, dim=axis)

    @staticmethod
    def contiguous(a: Any) -> Any:
        return a.contiguous()

    def stack_cols(self, cols: list[Any]) -> Any:
        return self.torch.stack(cols, 1)

    def stack(self, arrays: list[Any], axis: int) -> Any:
        return self.torch.stack(arrays, dim=axis)

    def clip(self, a: Any, lo: float, hi: float) -> Any:
        return self.torch.clamp(a, lo, hi)

    def sqrt(self, a: Any) -> Any:
        return self.torch.sqrt(a)

    def abs(self, a: Any) -> Any:
        return self.torch.abs(a)

    def where(self, c: Any, a: Any, b: Any) -> Any:
        t = self.torch
        if not isinstance(a, t.Tensor):
            a = t.as_tensor(a, dtype=t.float64, device=self.device)
        if not isinstance(b, t.Tensor):
            b = t.as_tensor(b, dtype=t.float64, device=self.device)
        return t.where(c, a, b)

    def isfinite(self, a: Any) -> Any:
        return self.torch.isfinite(a)

    def maximum(self, a: Any, b: Any) -> Any:
        t = self.torch
        if not isinstance(b, t.Tensor):
            b = t.as_tensor(b, dtype=t.float64, device=self.device)
        return t.maximum(a, b)


_NUMPY_OPS = _Numpy()


def backend_for(device: Any) -> Any:
    """The array backend of ``device``: ``None`` -> numpy (CPU, float64); a torch device
    (``"cpu"``, ``"cuda"``, ``"cuda:1"`` or a ``torch.device``) -> torch float64 there."""
    if device is None:
        return _NUMPY_OPS
    import torch

    try:
        dev = torch.device(device)
    except (TypeError, RuntimeError) as err:
        raise InputError(f"device must be None (numpy) or a torch device such as 'cpu' or "
                         f"'cuda', got {short(repr(device), 80)}") from err
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device {short(repr(device), 80)} asked for, but torch sees no CUDA "
                         "device here")
    return _Torch(dev)

