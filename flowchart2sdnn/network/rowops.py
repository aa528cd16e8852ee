"""Operations on the rows of the RTRL sensitivity buffers, four float64 lanes at a time.

A row is the sensitivity of one neuron with respect to every theta, a C-contiguous float64 vector whose length
is P rounded up to a multiple of :data:`LANES` (:func:`padded`); nothing reads the padding lanes (zero, or NaN
after a non-finite weight: lanes never mix). P is small (3 to a few dozen), and LLVM's loop vectorizer does
not help there: it needs a multiple of its vector width times its interleave count (16 or more iterations)
and runtime alias checks before each loop, so rows of 15 ran scalar, each behind a vectorization preamble.
numba leaves LLVM's SLP vectorizer off, so unrolled scalar code stays scalar too. These intrinsics emit the
``<4 x double>`` loads, arithmetic and stores directly.

Every lane does what the scalar loop did (``dst[p] + w * src[p]``, ``g * src[p]``) with the caller's
fastmath flags (numba sets them on every float instruction of the function it compiles), so results are the
same bits: with "contract" a fused multiply-add, as the scalar code had, without it a multiply and an add.
"""

from __future__ import annotations

import numba
from llvmlite import ir
from numba.core import cgutils, types
from numba.core.errors import TypingError
from numba.extending import intrinsic

__all__ = ["LANES", "padded", "axpy", "emit"]

#: Lanes per vector operation; rows are padded to a multiple of this.
LANES = 4

_V = ir.VectorType(ir.DoubleType(), LANES)


@numba.njit(cache=True)
def padded(n_theta):
    """Row length for `n_theta` parameters: the next multiple of :data:`LANES` (at least one vector)."""
    return max(LANES, (n_theta + LANES - 1) // LANES * LANES)


def _check(*arrays) -> None:
    for a in arrays:
        if not (isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and a.dtype == types.float64):
            raise TypingError(f"row operations need C-contiguous 1-D float64 rows, got {a}")


def _codegen(op: str):
    """dst, scalar, src -> loop over the row in vectors: "axpy" dst += s * src; "emit" dst = s * src, src = 0."""

    def codegen(context, builder, sig, args):
        dst = context.make_array(sig.args[0])(context, builder, args[0])
        src = context.make_array(sig.args[2])(context, builder, args[2])
        intp = context.get_value_type(types.intp)
        n_vec = builder.udiv(builder.extract_value(dst.shape, 0), ir.Constant(intp, LANES))
        lane0 = builder.insert_element(ir.Constant(_V, ir.Undefined), args[1], ir.Constant(ir.IntType(32), 0))
        scalar = builder.shuffle_vector(lane0, ir.Constant(_V, ir.Undefined),
                                        ir.Constant(ir.VectorType(ir.IntType(32), LANES), [0] * LANES))
        with cgutils.for_range(builder, n_vec) as loop:
            offset = builder.mul(loop.index, ir.Constant(intp, LANES))
            p_dst = builder.bitcast(builder.gep(dst.data, [offset], inbounds=True), _V.as_pointer())
            p_src = builder.bitcast(builder.gep(src.data, [offset], inbounds=True), _V.as_pointer())
            product = builder.fmul(scalar, builder.load(p_src, align=8))
            if op == "axpy":
                builder.store(builder.fadd(builder.load(p_dst, align=8), product), p_dst, align=8)
            else:
                builder.store(product, p_dst, align=8)
                builder.store(ir.Constant(_V, [0.0] * LANES), p_src, align=8)
        return context.get_dummy_value()

    return codegen


@intrinsic
def axpy(typingctx, dst, w, src):
    """``dst += w * src`` over the padded row (``len(dst)`` a multiple of LANES, ``len(src) >= len(dst)``)."""
    _check(dst, src)
    return types.void(dst, types.float64, src), _codegen("axpy")


@intrinsic
def emit(typingctx, dst, g, src):
    """``dst = g * src``, then ``src = 0`` (the accumulator is ready for the next neuron); padded rows."""
    _check(dst, src)
    return types.void(dst, types.float64, src), _codegen("emit")
