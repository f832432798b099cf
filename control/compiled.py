"""CasADi SX functions compiled to machine code and evaluated on fixed numpy arrays.

CasADi evaluates an SX Function by interpreting its algorithm, a list of scalar
instructions, in a virtual machine; :class:`~trackmj.control.fastcall.BufferedFunction`
removes the Python conversions around a call but not the interpreter. Here the same
instruction list becomes straight-line LLVM code, one LLVM instruction per SX instruction
in the algorithm's order (``x*x`` for ``sq``, ``x+x`` for ``twice``, ``fmax``/``fmin``
with glibc's rules for NaN and signed zeros, ``llvm.sqrt``/``llvm.fabs``, no fast-math),
so it performs the same IEEE operations on the same operands: its results equal the
virtual machine's bit for bit (tested), 3-5x faster (qp data of the NMPC's SQP 24 ->
4.6 µs, the EKF step 3.0 -> 1.0 µs, hot), and its code is a fraction of the interpreter's
memory traffic.

The code is emitted by a numba ``intrinsic`` inside a generated module with one
``njit(cache=True)`` kernel taking one int64 array: the addresses of the bound input,
result and constants arrays. Constants are read from that array, not embedded, so every
function with the same instruction structure (e.g. another bulk modulus or horizon
weights) shares one compiled kernel. The module is written once per structure into
``<trackmj cache>/compiled/`` (:func:`trackmj.io.cache_dir`), named by the
SHA-256 of the structure and of this file's source (an edit here makes a new name, so
numba's cache, which checks only the generated file, is never stale); numba keeps the
machine code beside it. First compile ~0.2-2.5 s per function (LLVM on up to ~13k
instructions), later processes load it in milliseconds.

:func:`bind` returns a :class:`CompiledFunction` where every instruction is supported and
numba is active, else the :class:`BufferedFunction` (``TRACKMJ_NO_COMPILE=1`` forces the
latter, e.g. to compare).
"""

from __future__ import annotations

import base64
import functools
import hashlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

import casadi as ca
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils, config
from numba.extending import intrinsic
from numpy.typing import NDArray

from trackmj.control.fastcall import BufferedFunction
from trackmj.io import cache_dir, write_text_atomic

DISABLE_ENV = "TRACKMJ_NO_COMPILE"
"""Set to 1 to evaluate every SX function in CasADi's virtual machine instead."""

_BINARY = {ca.OP_ADD: "fadd", ca.OP_SUB: "fsub", ca.OP_MUL: "fmul", ca.OP_DIV: "fdiv"}
_UNARY = (ca.OP_NEG, ca.OP_SQ, ca.OP_TWICE, ca.OP_INV, ca.OP_SQRT, ca.OP_FABS)
_MINMAX = (ca.OP_FMAX, ca.OP_FMIN)
SUPPORTED = frozenset((*_BINARY, *_UNARY, *_MINMAX, ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT))
"""SX operations the emitter translates (what the OCP, SQP and estimators use)."""


def instructions(fn: ca.Function) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The SX algorithm of ``fn`` as rows (op, a, b, c) and its constants.

    OP_INPUT: w[a] = arg[b][c]; OP_OUTPUT: res[b][c] = w[a]; OP_CONST: w[a] = const[b];
    otherwise w[a] = op(w[b], w[c]) (c = -1 for a unary op). NotImplementedError for an
    operation outside :data:`SUPPORTED` or a function that is not an SXFunction.
    """
    if fn.class_name() != "SXFunction":
        raise NotImplementedError(f"{fn.name()}: {fn.class_name()} is not an SX function")
    if fn.has_free():
        raise NotImplementedError(f"{fn.name()}: free variables")
    rows, consts = [], []
    for k in range(fn.n_instructions()):
        op = fn.instruction_id(k)
        if op not in SUPPORTED:
            raise NotImplementedError(f"{fn.name()}: SX operation {op} is not compiled")
        ins, outs = fn.instruction_input(k), fn.instruction_output(k)
        if op == ca.OP_INPUT:
            rows.append((op, outs[0], ins[0], ins[1]))
        elif op == ca.OP_OUTPUT:
            rows.append((op, ins[0], outs[0], outs[1]))
        elif op == ca.OP_CONST:
            rows.append((op, outs[0], len(consts), 0))
            consts.append(fn.instruction_constant(k))
        elif op in _BINARY or op in _MINMAX:
            rows.append((op, outs[0], ins[0], ins[1]))
        else:
            rows.append((op, outs[0], ins[0], -1))
    return np.array(rows, dtype=np.int64).reshape(-1, 4), np.array(consts, dtype=float)


def _emit(builder: Any, base: Any, rows: NDArray[np.int64], n_in: int, n_out: int,
          in_place: bool) -> None:
    """Straight-line LLVM for ``rows`` (see :func:`instructions`); ``base`` points to the
    int64 addresses of the arguments, results and constants. ``in_place``: every result is
    stored after the last input is read (results may be bound to inputs)."""
    dbl, i64 = ir.DoubleType(), ir.IntType(64)
    ptr = dbl.as_pointer()
    module = builder.module
    sqrt = module.declare_intrinsic("llvm.sqrt", [dbl])
    fabs = module.declare_intrinsic("llvm.fabs", [dbl])
    one = ir.Constant(dbl, 1.0)

    def address(i: int) -> Any:
        return builder.inttoptr(builder.load(builder.gep(base, [ir.Constant(i64, i)])), ptr)

    args = [address(i) for i in range(n_in)]
    res = [address(n_in + i) for i in range(n_out)]
    const = address(n_in + n_out)
    b, w, stores = builder, {}, []
    for op, a, x, y in rows.tolist():
        if op == ca.OP_INPUT:
            w[a] = b.load(b.gep(args[x], [ir.Constant(i64, y)]))
        elif op == ca.OP_OUTPUT:
            if in_place:
                stores.append((w[a], x, y))
            else:
                b.store(w[a], b.gep(res[x], [ir.Constant(i64, y)]))
        elif op == ca.OP_CONST:
            w[a] = b.load(b.gep(const, [ir.Constant(i64, x)]))
        elif op in _BINARY:
            w[a] = getattr(b, _BINARY[op])(w[x], w[y])
        elif op in _MINMAX:
            # std::fmax/fmin as CasADi's glibc computes them: u if u >= v (u <= v), so
            # u on a tie of signed zeros; v if u is NaN; u if v is NaN
            u, v = w[x], w[y]
            wins = b.fcmp_ordered(">=" if op == ca.OP_FMAX else "<=", u, v)
            w[a] = b.select(b.or_(wins, b.fcmp_unordered("uno", v, v)), u, v)
        elif op == ca.OP_NEG:
            w[a] = b.fneg(w[x])
        elif op == ca.OP_SQ:
            w[a] = b.fmul(w[x], w[x])
        elif op == ca.OP_TWICE:
            w[a] = b.fadd(w[x], w[x])
        elif op == ca.OP_INV:
            w[a] = b.fdiv(one, w[x])
        elif op == ca.OP_SQRT:
            w[a] = b.call(sqrt, [w[x]])
        else:   # OP_FABS
            w[a] = b.call(fabs, [w[x]])
    for value, x, y in stores:
        b.store(value, b.gep(res[x], [ir.Constant(i64, y)]))


def intrinsic_from(encoded: str, n_in: int, n_out: int, in_place: bool = False) -> Any:
    """The numba intrinsic ``body(addresses)`` that evaluates the rows ``encoded`` (base64
    of int64 rows, see :func:`instructions`; ``in_place`` as in :func:`_emit`); used by
    the generated modules."""
    rows = np.frombuffer(base64.b64decode(encoded), dtype=np.int64).reshape(-1, 4)

    @intrinsic
    def body(typingctx: Any, addresses: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            array = cgutils.create_struct_proxy(signature.args[0])(context, builder,
                                                                   value=args[0])
            _emit(builder, array.data, rows, n_in, n_out, in_place)
            return context.get_dummy_value()

        return types.void(addresses), codegen

    return body


_MODULE = '''"""Generated by trackmj.control.compiled from the CasADi SX function {name!r}
({count} instructions, {n_in} inputs, {n_out} outputs, in place: {in_place}); do not
edit."""
import numba

from trackmj.control.compiled import intrinsic_from

_body = intrinsic_from("{encoded}", {n_in}, {n_out}, {in_place})


@numba.njit(cache=True, nogil=True)
def kernel(addresses):
    _body(addresses)
'''


@functools.cache
def _emitter_digest() -> str:
    """SHA-256 of this file: the generated modules' names depend on it."""
    return hashlib.sha256(Path(__file__).read_bytes()).hexdigest()


def _directory() -> Path:
    """Where the generated modules live (the trackmj cache, else a temporary directory)."""
    for path in (cache_dir() / "compiled",
                 Path(tempfile.gettempdir()) / f"trackmj-compiled-{os.getuid()}"):
        try:
            path.mkdir(parents=True, exist_ok=True)
            if os.access(path, os.W_OK):
                return path
        except OSError:
            continue
    raise OSError("no writable directory for the compiled SX kernels")


_modules: dict[str, ModuleType] = {}


def _module(fn: ca.Function, rows: NDArray[np.int64], in_place: bool) -> ModuleType:
    """The generated module of ``fn``'s structure (written if new, imported once)."""
    n_in, n_out = fn.n_in(), fn.n_out()
    digest = hashlib.sha256(f"{_emitter_digest()} {n_in} {n_out} {in_place}".encode()
                            + rows.tobytes()).hexdigest()[:32]
    name = f"trackmj_sx_{digest}"
    if name in _modules:
        return _modules[name]
    path = _directory() / f"{name}.py"
    if not path.exists():   # written whole, then renamed: concurrent workers may race
        write_text_atomic(path, _MODULE.format(
            name=fn.name(), count=len(rows), n_in=n_in, n_out=n_out, in_place=in_place,
            encoded=base64.b64encode(rows.tobytes()).decode()))
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module    # numba's cache rebuilds the kernel's globals by name
    spec.loader.exec_module(module)
    _modules[name] = module
    return module


class CompiledFunction:
    """``fn`` compiled (see the module docstring) and bound to the input arrays ``args``
    and to result arrays (``res`` or new zero vectors), each holding the nonzeros of its
    input/output in column-major order; the same contract as ``BufferedFunction``: keep
    the bound arrays (update them in place, never rebind them). ``call`` holds this object,
    so keeping ``call`` alone keeps the arrays it points at alive. A result may be bound to an
    input array (updated in place: every input is read before the first result is written).

    ``call()`` (or the instance) evaluates in place and returns None.
    """

    def __init__(self, fn: ca.Function, args: list[NDArray[np.float64]],
                 res: list[NDArray[np.float64]] | None = None) -> None:
        rows, self.constants = instructions(fn)
        self.args = args
        self.res = res if res is not None else [np.zeros(fn.nnz_out(i))
                                                for i in range(fn.n_out())]
        if len(args) != fn.n_in() or len(self.res) != fn.n_out():
            raise ValueError(f"{fn.name()}: {fn.n_in()} arguments and {fn.n_out()} results "
                             "must be bound")
        for kind, arrays, nnz in (("argument", args, fn.nnz_in),
                                  ("result", self.res, fn.nnz_out)):
            for i, a in enumerate(arrays):
                if a.dtype != np.float64 or not a.flags.c_contiguous or a.size != nnz(i):
                    raise ValueError(f"{fn.name()}: {kind} {i} must be a contiguous float64 "
                                     f"array of {nnz(i)} values")
        # a constant-free function still gets a (one-element) constants array to point at
        self._constants = self.constants if self.constants.size else np.zeros(1)
        self.addresses = np.array([a.ctypes.data for a in (*args, *self.res,
                                                            self._constants)],
                                  dtype=np.int64)
        in_place = any(np.may_share_memory(r, a) for r in self.res for a in args)
        kernel = _module(fn, rows, in_place).kernel
        kernel.compile((types.Array(types.int64, 1, "C"),))   # now, not at the first call
        self.call = functools.partial(kernel, self.addresses)
        # the kernel reads raw addresses: whoever keeps only ``call`` keeps every array too
        # (the constants would otherwise be freed with this object, and the memory reused)
        self.call.bound = self  # pyright: ignore[reportAttributeAccessIssue]

    def __call__(self) -> None:
        self.call()


class AliasedBuffer:
    """CasADi's buffer (:class:`BufferedFunction`) for results bound to inputs: the virtual
    machine writes results while it still reads inputs, so it writes private arrays that
    are copied onto the bound ones after each evaluation."""

    def __init__(self, fn: ca.Function, args: list[NDArray[np.float64]],
                 res: list[NDArray[np.float64]]) -> None:
        self.args, self.res = args, res
        self._buffered = BufferedFunction(fn, args, [np.zeros_like(r) for r in res])
        self._copies = list(zip(self._buffered.res, res, strict=True))
        self.call = self.__call__

    def __call__(self) -> int:
        status = self._buffered()
        for private, bound in self._copies:
            bound[...] = private
        return status


def compiling() -> bool:
    """Whether :func:`bind` compiles (numba active and ``TRACKMJ_NO_COMPILE`` unset)."""
    if os.environ.get(DISABLE_ENV, "") not in ("", "0"):
        return False
    return not config.DISABLE_JIT  # pyright: ignore[reportAttributeAccessIssue]  # set at import


Bound = CompiledFunction | BufferedFunction | AliasedBuffer
"""What :func:`bind` returns: calling it (or its ``call``) evaluates in place."""


def bind(fn: ca.Function, args: list[NDArray[np.float64]],
         res: list[NDArray[np.float64]] | None = None) -> Bound:
    """``fn`` bound to ``args``/``res`` (results may be bound to inputs): compiled where
    possible, else CasADi's buffer."""
    if compiling():
        try:
            return CompiledFunction(fn, args, res)
        except NotImplementedError:
            pass
    if res is not None and any(np.may_share_memory(r, a) for r in res for a in args):
        return AliasedBuffer(fn, args, res)
    return BufferedFunction(fn, args, res)
