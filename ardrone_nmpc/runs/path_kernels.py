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
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import OUTER_KERNEL

__all__ = ["polyline_distances_m"]


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
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        q0, q1, q2 = p[i, 0], p[i, 1], p[i, 2]
        best = math.inf
        for s in range(n_seg):
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
        out[i] = math.sqrt(best)
    return out


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
