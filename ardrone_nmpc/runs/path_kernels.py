"""Distances of positions from a polyline, compiled: the inner loop of
:func:`~ardrone_nmpc.runs.metrics.path_deviation` (every path run's summary measures ~1000
positions against a ~200-vertex polyline: 7 ms in numpy's chunked broadcasting, ~0.5 ms here).

The same arithmetic as the numpy form it replaced, operation by operation: ``ap = q − a``,
``u = clip((ap·ab)·inv, 0, 1)``, ``diff = ap − u·ab``, ``d² = diff·diff``,
``inv = 1/(ab·ab)`` (0 for a zero-length segment), the minimum over the segments, then its
square root. The
three-term dot products are summed ``(x₀ + x₂) + x₁``: the order numpy's ``einsum`` takes on
AVX2 and AVX-512 machines (its 4- and 8-lane sums add lane 2 to lane 0 first), so the
distances are the bits the numpy form gave there — and, compiled for the pinned target
(:mod:`ardrone_nmpc.core.numerics`), the same on every CPU (numpy's own order differs on a
CPU without AVX2). ``tests/unit/test_path_kernels.py`` holds the kernel to that numpy form.

Pruned, not reordered: the segments are grouped in chunks of :data:`CHUNK_SEGMENTS`, and a
chunk whose bounding box lies farther from the position than the nearest segment found yet
(by a margin far above rounding) is skipped, the previous position's chunk looked at first.
A skipped segment's distance could not have been the minimum, and the minimum of the others
is the same value whatever their order: the same bits, ~5× fewer segments measured.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import OUTER_KERNEL

__all__ = ["polyline_distances_m"]


#: Segments per box of the pruning (module doc): ~14 boxes for a 200-vertex path.
CHUNK_SEGMENTS = 16
#: A box is skipped only when it is this far beyond the nearest segment yet (m², relative
#: and absolute): some 10⁶ times the rounding of either distance, so a skipped segment's
#: computed distance could never have been the minimum.
_REL_MARGIN = 1e-6
_ABS_MARGIN_M2 = 1e-9
#: Coordinates (m) up to this keep every product of a distance finite: a box with a vertex
#: beyond it, or a segment whose 1/(ab·ab) overflows (shorter than ~1e-154 m), is never
#: skipped, nor any box for a position beyond it — there a segment's squared distance can be
#: NaN (inf·0, inf − inf, 0·inf) however far its box is, and unpruned the NaN is the answer.
_SAFE_M = 1e150


@njit(cache=True, **OUTER_KERNEL)
def polyline_distances_m(p, poly):
    """Distance (m) of each row of ``p`` (K, 3) from the polyline ``poly`` (M ≥ 2, 3): to the
    nearest point of the nearest segment. NaN where a squared distance is NaN."""
    n_seg = poly.shape[0] - 1
    ab = np.empty((n_seg, 3))
    inv = np.empty(n_seg)
    for s in range(n_seg):
        ab[s, 0] = poly[s + 1, 0] - poly[s, 0]
        ab[s, 1] = poly[s + 1, 1] - poly[s, 1]
        ab[s, 2] = poly[s + 1, 2] - poly[s, 2]
        ab2 = (ab[s, 0] * ab[s, 0] + ab[s, 2] * ab[s, 2]) + ab[s, 1] * ab[s, 1]
        inv[s] = 1.0 / ab2 if ab2 > 0.0 else 0.0  # zero length: u = 0
    # the box of each chunk of segments: its vertices' extent (a segment lies within it)
    n_box = (n_seg + CHUNK_SEGMENTS - 1) // CHUNK_SEGMENTS
    lo = np.empty((n_box, 3))
    hi = np.empty((n_box, 3))
    for c in range(n_box):
        finite = True
        for k in range(3):
            lo[c, k], hi[c, k] = math.inf, -math.inf
            for v in range(c * CHUNK_SEGMENTS, min((c + 1) * CHUNK_SEGMENTS, n_seg) + 1):
                x = poly[v, k]
                if not abs(x) <= _SAFE_M:  # NaN and ±inf included
                    finite = False
                if x < lo[c, k]:
                    lo[c, k] = x
                if x > hi[c, k]:
                    hi[c, k] = x
        for s in range(c * CHUNK_SEGMENTS, min((c + 1) * CHUNK_SEGMENTS, n_seg)):
            if not math.isfinite(inv[s]):
                finite = False
        if not finite:  # a vertex not finite (or huge), a tiny segment: never skipped
            for k in range(3):
                lo[c, k], hi[c, k] = -math.inf, math.inf
    out = np.empty(p.shape[0])
    start = 0  # the box of the previous position's nearest segment: looked at first
    for i in range(p.shape[0]):
        q0, q1, q2 = p[i, 0], p[i, 1], p[i, 2]
        best = math.inf
        best_box = start
        # a position beyond _SAFE_M (or NaN): every box measured (never skipped)
        prune = abs(q0) <= _SAFE_M and abs(q1) <= _SAFE_M and abs(q2) <= _SAFE_M
        for j in range(n_box):
            c = start + j
            if c >= n_box:
                c -= n_box
            g0 = max(lo[c, 0] - q0, 0.0, q0 - hi[c, 0])
            g1 = max(lo[c, 1] - q1, 0.0, q1 - hi[c, 1])
            g2 = max(lo[c, 2] - q2, 0.0, q2 - hi[c, 2])
            if prune and ((g0 * g0 + g2 * g2) + g1 * g1
                          > best * (1.0 + _REL_MARGIN) + _ABS_MARGIN_M2):
                continue  # every segment of the box is farther than the nearest one yet
            for s in range(c * CHUNK_SEGMENTS, min((c + 1) * CHUNK_SEGMENTS, n_seg)):
                ap0 = q0 - poly[s, 0]
                ap1 = q1 - poly[s, 1]
                ap2 = q2 - poly[s, 2]
                b0, b1, b2 = ab[s, 0], ab[s, 1], ab[s, 2]
                u = ((ap0 * b0 + ap2 * b2) + ap1 * b1) * inv[s]
                if u < 0.0:  # np.clip(u, 0, 1)
                    u = 0.0
                elif u > 1.0:
                    u = 1.0
                d0 = ap0 - u * b0
                d1 = ap1 - u * b1
                d2 = ap2 - u * b2
                dd = (d0 * d0 + d2 * d2) + d1 * d1
                if math.isnan(dd):  # numpy's min propagates a NaN
                    best = math.nan
                    break
                if dd < best:
                    best = dd
                    best_box = c
            if math.isnan(best):
                break
        start = best_box
        out[i] = math.sqrt(best)
    return out


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
