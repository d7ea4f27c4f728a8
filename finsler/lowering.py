"""Lowering of CasADi SX functions to vectorised numpy / torch programs.

A CasADi ``SXFunction`` is a straight-line program over scalars (its
*instruction list*). Executing the same instruction list with every scalar
replaced by a batch array gives a vectorised evaluator: one array operation per
instruction, no Python loop over points. The program is generated as Python
source once per function and compiled with `compile`, then cached.

The generated program is batch-first: every input is an array of shape
``(N, n_i)`` (or ``(n_i,)`` for a single point), every output of shape
``(N, m_o)``. With torch tensors it runs on the tensors' device and is
differentiable (autograd records the same operations).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["LoweredFunction", "lower", "max_through_abs"]


def _op(name: str) -> int:
    return int(getattr(ca, "OP_" + name))


# Unary operations: template with {0} the argument.
_UNARY: dict[int, str] = {
    _op("ASSIGN"): "{0}",
    _op("NEG"): "-{0}",
    _op("EXP"): "B.exp({0})",
    _op("LOG"): "B.log({0})",
    _op("SQRT"): "B.sqrt({0})",
    _op("SQ"): "({0}*{0})",
    _op("TWICE"): "(2.0*{0})",
    _op("SIN"): "B.sin({0})",
    _op("COS"): "B.cos({0})",
    _op("TAN"): "B.tan({0})",
    _op("ASIN"): "B.asin({0})",
    _op("ACOS"): "B.acos({0})",
    _op("ATAN"): "B.atan({0})",
    _op("NOT"): "B.logical_not({0})",
    _op("FLOOR"): "B.floor({0})",
    _op("CEIL"): "B.ceil({0})",
    _op("FABS"): "B.abs({0})",
    _op("SIGN"): "B.sign({0})",
    _op("ERF"): "B.erf({0})",
    _op("INV"): "(1.0/{0})",
    _op("SINH"): "B.sinh({0})",
    _op("COSH"): "B.cosh({0})",
    _op("TANH"): "B.tanh({0})",
    _op("ASINH"): "B.asinh({0})",
    _op("ACOSH"): "B.acosh({0})",
    _op("ATANH"): "B.atanh({0})",
    _op("LOG1P"): "B.log1p({0})",
    _op("EXPM1"): "B.expm1({0})",
}

# Binary operations: template with {0}, {1} the arguments.
_BINARY: dict[int, str] = {
    _op("ADD"): "({0}+{1})",
    _op("SUB"): "({0}-{1})",
    _op("MUL"): "({0}*{1})",
    _op("DIV"): "({0}/{1})",
    _op("POW"): "B.pow({0},{1})",
    _op("CONSTPOW"): "B.pow({0},{1})",
    _op("LT"): "B.lt({0},{1})",
    _op("LE"): "B.le({0},{1})",
    _op("EQ"): "B.eq({0},{1})",
    _op("NE"): "B.ne({0},{1})",
    _op("AND"): "B.logical_and({0},{1})",
    _op("OR"): "B.logical_or({0},{1})",
    _op("FMOD"): "B.fmod({0},{1})",
    _op("COPYSIGN"): "B.copysign({0},{1})",
    _op("IF_ELSE_ZERO"): "B.if_else_zero({0},{1})",
    _op("FMIN"): "B.minimum({0},{1})",
    _op("FMAX"): "B.maximum({0},{1})",
    _op("ATAN2"): "B.atan2({0},{1})",
    _op("HYPOT"): "B.hypot({0},{1})",
}

_OP_CONST = _op("CONST")
_OP_INPUT = _op("INPUT")
_OP_OUTPUT = _op("OUTPUT")


class _NumpyBackend:
    """Array operations of the generated program, for numpy float64 arrays."""

    exp, log, sqrt, sin, cos, tan = np.exp, np.log, np.sqrt, np.sin, np.cos, np.tan
    asin, acos, atan, atan2 = np.arcsin, np.arccos, np.arctan, np.arctan2
    sinh, cosh, tanh = np.sinh, np.cosh, np.tanh
    asinh, acosh, atanh = np.arcsinh, np.arccosh, np.arctanh
    floor, ceil, abs, sign = np.floor, np.ceil, np.abs, np.sign
    log1p, expm1, hypot, copysign, fmod = np.log1p, np.expm1, np.hypot, np.copysign, np.fmod
    minimum, maximum, pow = np.minimum, np.maximum, np.power

    @staticmethod
    def erf(a: Any) -> Any:
        from scipy.special import erf

        return erf(a)

    @staticmethod
    def lt(a: Any, b: Any) -> Any:
        return np.less(a, b).astype(np.float64)

    @staticmethod
    def le(a: Any, b: Any) -> Any:
        return np.less_equal(a, b).astype(np.float64)

    @staticmethod
    def eq(a: Any, b: Any) -> Any:
        return np.equal(a, b).astype(np.float64)

    @staticmethod
    def ne(a: Any, b: Any) -> Any:
        return np.not_equal(a, b).astype(np.float64)

    @staticmethod
    def logical_not(a: Any) -> Any:
        return np.logical_not(a).astype(np.float64)

    @staticmethod
    def logical_and(a: Any, b: Any) -> Any:
        return np.logical_and(a, b).astype(np.float64)

    @staticmethod
    def logical_or(a: Any, b: Any) -> Any:
        return np.logical_or(a, b).astype(np.float64)

    @staticmethod
    def if_else_zero(c: Any, a: Any) -> Any:
        return np.where(np.asarray(c) != 0, a, 0.0)


class _TorchBackend:
    """Array operations of the generated program, for torch tensors."""

    def __init__(self) -> None:
        import torch

        self.torch = torch
        t = torch
        self.exp, self.log, self.sqrt, self.sin, self.cos = t.exp, t.log, t.sqrt, t.sin, t.cos
        self.tan, self.asin, self.acos, self.atan = t.tan, t.asin, t.acos, t.atan
        self.sinh, self.cosh, self.tanh = t.sinh, t.cosh, t.tanh
        self.asinh, self.acosh, self.atanh = t.asinh, t.acosh, t.atanh
        self.floor, self.ceil, self.abs, self.sign = t.floor, t.ceil, t.abs, t.sign
        self.log1p, self.expm1, self.erf = t.log1p, t.expm1, t.erf

    def _pair(self, a: Any, b: Any) -> tuple[Any, Any]:
        t = self.torch
        if not isinstance(a, t.Tensor):
            a = t.as_tensor(a, dtype=b.dtype, device=b.device)
        if not isinstance(b, t.Tensor):
            b = t.as_tensor(b, dtype=a.dtype, device=a.device)
        return a, b

    def atan2(self, a: Any, b: Any) -> Any:
        return self.torch.atan2(*self._pair(a, b))

    def hypot(self, a: Any, b: Any) -> Any:
        return self.torch.hypot(*self._pair(a, b))

    def copysign(self, a: Any, b: Any) -> Any:
        return self.torch.copysign(*self._pair(a, b))

    def fmod(self, a: Any, b: Any) -> Any:
        return self.torch.fmod(*self._pair(a, b))

    def minimum(self, a: Any, b: Any) -> Any:
        return self.torch.minimum(*self._pair(a, b))

    def maximum(self, a: Any, b: Any) -> Any:
        return self.torch.maximum(*self._pair(a, b))

    def pow(self, a: Any, b: Any) -> Any:
        if isinstance(b, float) and b == 2.0:
            return a * a
        return self.torch.pow(a, b)

    def _cmp(self, fn: Callable[[Any, Any], Any], a: Any, b: Any) -> Any:
        a, b = self._pair(a, b)
        return fn(a, b).to(a.dtype)

    def lt(self, a: Any, b: Any) -> Any:
        return self._cmp(self.torch.lt, a, b)

    def le(self, a: Any, b: Any) -> Any:
        return self._cmp(self.torch.le, a, b)

    def eq(self, a: Any, b: Any) -> Any:
        return self._cmp(self.torch.eq, a, b)

    def ne(self, a: Any, b: Any) -> Any:
        return self._cmp(self.torch.ne, a, b)

    def logical_not(self, a: Any) -> Any:
        return (a == 0).to(a.dtype)

    def logical_and(self, a: Any, b: Any) -> Any:
        return self._cmp(self.torch.logical_and, a, b)

    def logical_or(self, a: Any, b: Any) -> Any:
        return self._cmp(self.torch.logical_or, a, b)

    def if_else_zero(self, c: Any, a: Any) -> Any:
        c, a = self._pair(c, a)
        return self.torch.where(c != 0, a, self.torch.zeros_like(a))


_NUMPY = _NumpyBackend()
_TORCH: _TorchBackend | None = None


def _torch_backend() -> _TorchBackend:
    global _TORCH
    if _TORCH is None:
        _TORCH = _TorchBackend()
    return _TORCH


@dataclass(frozen=True)
class LoweredFunction:
    """A CasADi SX function lowered to a vectorised Python program.

    Call it with numpy arrays or torch tensors, one per input of the CasADi
    function, each of shape ``(N, n_i)`` (broadcastable along the batch) or
    ``(n_i,)``; it returns one array per output of shape ``(N, m_o)``, in the
    same library (and for torch, on the same device and differentiable).
    """

    name: str
    n_in: int
    n_out: int
    in_sizes: tuple[int, ...]
    out_sizes: tuple[int, ...]
    n_instructions: int
    source: str
    _program: Callable[..., Any]

    def __call__(self, *args: Any) -> tuple[Any, ...]:
        if len(args) != self.n_in:
            raise TypeError(f"{self.name}: expected {self.n_in} inputs, got {len(args)}")
        first = args[0]
        # by the type's module, not isinstance: importing torch to ask costs ~1.5 s of a
        # cold start in numpy-only callers (the CLI's exact solves)
        is_torch = type(first).__module__.startswith("torch")
        for k, (a, n) in enumerate(zip(args, self.in_sizes, strict=True)):
            if a.shape[-1] != n:
                raise ValueError(
                    f"{self.name}: input {k} must have last dimension {n}, got shape "
                    f"{tuple(a.shape)}"
                )
        if is_torch:
            import torch

            cols = [list(a.reshape(-1, a.shape[-1]).unbind(-1)) for a in args]
            outs = self._program(_torch_backend(), cols)
            batch = torch.broadcast_shapes(*(a.shape[:-1] for a in args))
            return tuple(_stack_torch(o, first).reshape(*batch, -1) for o in outs)
        arrs = [np.asarray(a, dtype=np.float64) for a in args]
        # coordinate-major contiguous columns: unit-stride operands run faster in numpy
        cols = [list(np.ascontiguousarray(a.reshape(-1, a.shape[-1]).T)) for a in arrs]
        outs = self._program(_NUMPY, cols)
        batch = np.broadcast_shapes(*(a.shape[:-1] for a in arrs))
        flat = (int(np.prod(batch)),)
        result = []
        for o in outs:
            full = [np.broadcast_to(np.asarray(c, dtype=np.float64), flat) for c in o]
            stacked = full[0][:, None] if len(full) == 1 else np.stack(full, -1)
            result.append(stacked.reshape(*batch, len(full)))
        return tuple(result)

    def run(self, backend: Any, columns: list[list[Any]]) -> tuple[list[Any], ...]:
        """Run the program on a caller's backend (the operations ``B.exp``, ``B.sqrt``,
        ... and the arithmetic operators of its values): ``columns[i][j]`` is coordinate
        ``j`` of input ``i``; returns one list of values per output coordinate. Used by
        `finsler.enclosures.intervals.enclose`."""
        return self._program(backend, columns)


def _stack_torch(cols: list[Any], like: Any) -> Any:
    import torch

    shapes = [c.shape for c in cols if isinstance(c, torch.Tensor)]
    shape = torch.broadcast_shapes(*shapes) if shapes else torch.Size([1])
    if len(cols) == 1 and isinstance(cols[0], torch.Tensor):
        return cols[0].expand(shape).unsqueeze(-1)
    full = []
    for c in cols:
        if not isinstance(c, torch.Tensor):
            c = torch.full(shape, float(c), dtype=like.dtype, device=like.device)
        full.append(c.expand(shape))
    return torch.stack(full, -1)


def _const(value: float) -> str:
    if math.isnan(value):
        return "float('nan')"
    if math.isinf(value):
        return "float('inf')" if value > 0 else "float('-inf')"
    return repr(float(value))


def lower(fn: ca.Function) -> LoweredFunction:
    """Lower a CasADi SX function (dense inputs and outputs) to a vectorised program."""
    if not fn.is_a("SXFunction"):
        fn = fn.expand()
    in_sizes = tuple(fn.nnz_in(i) for i in range(fn.n_in()))
    out_sizes = tuple(fn.nnz_out(i) for i in range(fn.n_out()))
    for i in range(fn.n_in()):
        if not fn.sparsity_in(i).is_dense():
            raise ValueError(f"lower: input {i} of {fn.name()} is not dense")
    lines = ["def program(B, I):"]
    out_exprs: list[list[str]] = [["0.0"] * n for n in out_sizes]
    # Work variables are named after CasADi's work-vector slots, which CasADi reuses once
    # a value is dead: rebinding a name frees the old array (every operation returns a new
    # array, so no aliasing can occur) and keeps the memory footprint small.
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        if op == _OP_OUTPUT:
            (w,) = fn.instruction_input(k)
            o, nz = fn.instruction_output(k)
            name = f"o{o}_{nz}"
            lines.append(f"    {name} = w{w}")
            out_exprs[o][nz] = name
            continue
        (w,) = fn.instruction_output(k)
        if op == _OP_INPUT:
            i, nz = fn.instruction_input(k)
            expr = f"I[{i}][{nz}]"
        elif op == _OP_CONST:
            expr = _const(fn.instruction_constant(k))
        elif op in _UNARY:
            (a,) = fn.instruction_input(k)[:1]
            expr = _UNARY[op].format(f"w{a}")
        elif op in _BINARY:
            a, b = fn.instruction_input(k)[:2]
            expr = _BINARY[op].format(f"w{a}", f"w{b}")
        else:
            raise NotImplementedError(f"lower: CasADi operation {op} is not supported")
        lines.append(f"    w{w} = {expr}")
    ret = ", ".join("[" + ", ".join(o) + "]" for o in out_exprs)
    lines.append(f"    return ({ret},)")
    source = "\n".join(lines) + "\n"
    namespace: dict[str, Any] = {}
    exec(compile(source, f"<lowered {fn.name()}>", "exec"), namespace)
    return LoweredFunction(
        name=fn.name(),
        n_in=fn.n_in(),
        n_out=fn.n_out(),
        in_sizes=in_sizes,
        out_sizes=out_sizes,
        n_instructions=fn.n_instructions(),
        source=source,
        _program=namespace["program"],
    )


_OP_FMAX, _OP_FMIN = _op("FMAX"), _op("FMIN")


def max_through_abs(fn: ca.Function) -> ca.Function:
    """The same function (dense SX inputs and outputs) with every ``fmax(a, b)`` written
    ``(a + b + |a - b|) / 2`` and ``fmin(a, b)`` as ``(a + b - |a - b|) / 2``: equal in exact
    arithmetic (and in float64 where one argument is 0, as in ``max(x, 0)``), for the
    programs of its derivatives. CasADi differentiates ``fmax`` into
    ``le(b, a) / (le(b, a) + le(a, b))``; on a box across the kink the interval extension
    divides by an interval holding 0, and the enclosure of the gradient is unbounded. The
    derivative of ``|x|`` is ``sign(x)``, whose extension is ``[-1, 1]`` there: the
    enclosure stays bounded and holds Clarke's generalised gradient."""
    if not fn.is_a("SXFunction"):
        fn = fn.expand()
    ins = []
    for i in range(fn.n_in()):
        if not fn.sparsity_in(i).is_dense():
            raise ValueError(f"max_through_abs: input {i} of {fn.name()} is not dense")
        ins.append(ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)))
    outs: list[list[Any]] = [[ca.SX(0.0)] * fn.nnz_out(o) for o in range(fn.n_out())]
    work: dict[int, Any] = {}
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        if op == _OP_OUTPUT:
            (w,) = fn.instruction_input(k)
            o, nz = fn.instruction_output(k)
            outs[o][nz] = work[w]
            continue
        (w,) = fn.instruction_output(k)
        if op == _OP_INPUT:
            i, nz = fn.instruction_input(k)
            work[w] = ins[i].nz[nz]
        elif op == _OP_CONST:
            work[w] = ca.SX(fn.instruction_constant(k))
        elif op in (_OP_FMAX, _OP_FMIN):
            a, b = (work[j] for j in fn.instruction_input(k)[:2])
            sign = 1.0 if op == _OP_FMAX else -1.0
            work[w] = 0.5 * (a + b + sign * ca.fabs(a - b))
        elif op in _UNARY:
            work[w] = ca.SX.unary(op, work[fn.instruction_input(k)[0]])
        elif op in _BINARY:
            a, b = fn.instruction_input(k)[:2]
            work[w] = ca.SX.binary(op, work[a], work[b])
        else:
            raise NotImplementedError(f"max_through_abs: CasADi operation {op} is not supported")
    out_sx = [ca.SX(fn.sparsity_out(o), ca.vertcat(*vals)) if vals else
              ca.SX(fn.sparsity_out(o)) for o, vals in enumerate(outs)]
    return ca.Function(fn.name(), ins, out_sx)
