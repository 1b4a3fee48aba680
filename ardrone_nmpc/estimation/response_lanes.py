"""The response fit's innermost loops two elements at a time (``response_kernels.fold_sample``).

A sample's model values at one delay are L lags × 2 axes, each folded into Σx, Σx², Σx·y:
22 floating-point operations an element pair, ~half of the fit's step (issue 26). The two
axes of a lag are adjacent doubles in every array, and each takes the same operations with
its own operands — what one SSE2 instruction does on two lanes (every x86-64 has SSE2: the
pinned target, ``core/numerics``). numba does not pair them itself (its SLP vectoriser is
off, and its loop vectoriser does not see through the views of one buffer), so this emits
the pairs: each lane's sub, mul and add is the IEEE operation the scalar code makes, on the
same operands in the same order, without fast-math flags (no contraction into an FMA, no
reassociation) — the same bits, lane by lane. The same for the grid's fit every refresh
(:func:`fit_pairs`, three divisions an element: the divider's lanes work two at a time).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["fit_pairs", "fold_lags"]


@intrinsic
def fold_lags(typingctx, sums, ylag, memo, e0, g0, r0, lags, kl2, u0, u1, y0, y1, forget,
              scale):
    """For m < ``lags``: the pair v = u + (ylag[g0 + 2m : +2] − u)·memo[r0 + m] (u = (u0,
    u1)) folded into ``sums`` at e = e0 + 2m (Σx), e + kl2 (Σx²: v·v) and e + 2·kl2 (Σx·y:
    v·(y0, y1)), each first multiplied by ``forget`` when ``scale`` — fold_sample's scalar
    expressions, lane by lane. Every index non-negative and in bounds (the caller's)."""
    sig = types.void(sums, ylag, memo, types.int64, types.int64, types.int64, types.int64,
                     types.int64, types.float64, types.float64, types.float64, types.float64,
                     types.float64, types.boolean)

    def codegen(context, builder, signature, args):
        (sums_a, ylag_a, memo_a, e0_v, g0_v, r0_v, lags_v, kl2_v, u0_v, u1_v, y0_v, y1_v,
         forget_v, scale_v) = args
        f64 = ir.DoubleType()
        pair = ir.VectorType(f64, 2)
        ppair = pair.as_pointer()
        i64 = ir.IntType(64)
        data = [context.make_array(t)(context, builder, a).data
                for t, a in zip(signature.args[:3], (sums_a, ylag_a, memo_a))]
        sums_p, ylag_p, memo_p = data

        def two(a, b):
            v = builder.insert_element(ir.Constant(pair, ir.Undefined), a, ir.Constant(i64, 0))
            return builder.insert_element(v, b, ir.Constant(i64, 1))

        u, y, f = two(u0_v, u1_v), two(y0_v, y1_v), two(forget_v, forget_v)

        def at(base, index):  # the pair at base[index], base[index + 1] (8-byte aligned)
            return builder.bitcast(builder.gep(base, [index]), ppair)

        def fold(ptr, add, scaled):
            s = builder.load(ptr, align=8)
            if scaled:
                s = builder.fmul(s, f)
            builder.store(builder.fadd(s, add), ptr, align=8)

        def body(scaled):
            with cgutils.for_range(builder, lags_v) as loop:
                m = loop.index
                m2 = builder.add(m, m)
                d = builder.load(builder.gep(memo_p, [builder.add(r0_v, m)]))
                yl = builder.load(at(ylag_p, builder.add(g0_v, m2)), align=8)
                v = builder.fadd(u, builder.fmul(builder.fsub(yl, u), two(d, d)))
                e = builder.add(e0_v, m2)
                fold(at(sums_p, e), v, scaled)
                q = builder.add(e, kl2_v)
                fold(at(sums_p, q), builder.fmul(v, v), scaled)
                fold(at(sums_p, builder.add(q, kl2_v)), builder.fmul(v, y), scaled)

        with builder.if_else(scale_v) as (then, otherwise):
            with then:
                body(True)
            with otherwise:
                body(False)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def fit_pairs(typingctx, state, out, head, points, kl2, n, sy0, sy1, syy0, syy1):
    """``response_kernels.fit_grid``'s loop over the ``points`` grid points, the two axes of
    each at once: from the sums at ``state[head:]`` (Σx, Σx², Σx·y, each ``kl2`` long) into
    ``out`` the centred Σx² c = Σx² − Σx·Σx / n, the gain (Σx·y − Σx·Σy / n) / c where
    c > 1e-12 (else 0), the residual Σy²_c − gain·cy (else Σy²_c) per axis and their sum
    (0 + r₀) + r₁ per point; True if any c > 1e-12. A lane's quotient is made on both lanes
    and the one not taken dropped (no trap: an x86 division by 0 answers inf or NaN); ``n``
    is not 0 (the caller divided by it first, which raises)."""
    sig = types.boolean(state, out, types.int64, types.int64, types.int64, types.float64,
                        types.float64, types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        state_a, out_a, head_v, points_v, kl2_v, n_v, sy0_v, sy1_v, syy0_v, syy1_v = args
        f64, i64 = ir.DoubleType(), ir.IntType(64)
        pair = ir.VectorType(f64, 2)
        st_p = context.make_array(signature.args[0])(context, builder, state_a).data
        out_p = context.make_array(signature.args[1])(context, builder, out_a).data

        def two(a, b):
            v = builder.insert_element(ir.Constant(pair, ir.Undefined), a, ir.Constant(i64, 0))
            return builder.insert_element(v, b, ir.Constant(i64, 1))

        def at(base, index):
            return builder.bitcast(builder.gep(base, [index]), pair.as_pointer())

        nn, sy, syy = two(n_v, n_v), two(sy0_v, sy1_v), two(syy0_v, syy1_v)
        tiny = ir.Constant(pair, [ir.Constant(f64, 1e-12)] * 2)
        zeros = ir.Constant(pair, [ir.Constant(f64, 0.0)] * 2)
        any_ok = cgutils.alloca_once_value(builder, ir.Constant(ir.IntType(1), 0))
        sx_p = builder.gep(st_p, [head_v])
        sxx_p, sxy_p = builder.gep(sx_p, [kl2_v]), builder.gep(sx_p, [builder.add(kl2_v, kl2_v)])
        gain_p = builder.gep(out_p, [kl2_v])
        rssa_p = builder.gep(gain_p, [kl2_v])
        rss_p = builder.gep(rssa_p, [kl2_v])
        with cgutils.for_range(builder, points_v) as loop:
            i = loop.index
            e = builder.add(i, i)
            v = builder.load(at(sx_p, e), align=8)
            c = builder.fsub(builder.load(at(sxx_p, e), align=8),
                             builder.fdiv(builder.fmul(v, v), nn))
            cy = builder.fsub(builder.load(at(sxy_p, e), align=8),
                              builder.fdiv(builder.fmul(v, sy), nn))
            builder.store(c, at(out_p, e), align=8)
            ok = builder.fcmp_ordered(">", c, tiny)
            g = builder.fdiv(cy, c)
            builder.store(builder.select(ok, g, zeros), at(gain_p, e), align=8)
            r = builder.select(ok, builder.fsub(syy, builder.fmul(g, cy)), syy)
            builder.store(r, at(rssa_p, e), align=8)
            r0 = builder.extract_element(r, ir.Constant(i64, 0))
            r1 = builder.extract_element(r, ir.Constant(i64, 1))
            total = builder.fadd(builder.fadd(ir.Constant(f64, 0.0), r0), r1)
            builder.store(total, builder.gep(rss_p, [i]))
            either = builder.or_(builder.extract_element(ok, ir.Constant(i64, 0)),
                                 builder.extract_element(ok, ir.Constant(i64, 1)))
            builder.store(builder.or_(builder.load(any_ok), either), any_ok)
        return builder.load(any_ok)

    return sig, codegen
