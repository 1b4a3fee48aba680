"""The compiled polyline distances (runs/path_kernels.py) against the numpy broadcasting they
replaced in ``runs.metrics.path_deviation``: bit for bit, over many random paths and the
flown square's positions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.runs.metrics import path_deviation
from ardrone_nmpc.runs.path_kernels import polyline_distances_m


def _numpy_distances(p: np.ndarray, poly: np.ndarray, chunk_elements: int = 32_768
                     ) -> np.ndarray:
    """The numpy form path_deviation had before the kernel (commit fb5eae3), verbatim."""
    a = poly[:-1]
    ab = poly[1:] - a
    ab2 = np.einsum("ij,ij->i", ab, ab)
    inv = np.divide(1.0, ab2, out=np.zeros_like(ab2), where=ab2 > 0.0)
    n_seg = a.shape[0]
    step = max(1, chunk_elements // n_seg)
    dist = np.empty(p.shape[0])
    for i in range(0, p.shape[0], step):
        q = p[i:i + step]
        ap = q[:, None, :] - a[None, :, :]
        u = np.clip(np.einsum("csk,sk->cs", ap, ab) * inv, 0.0, 1.0)
        diff = ap - u[:, :, None] * ab[None, :, :]
        d2 = np.einsum("csk,csk->cs", diff, diff)
        dist[i:i + step] = np.sqrt(d2.min(axis=1))
    return dist


def _python_distances(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """The kernel's order written out in Python floats (the CPU-independent statement), a
    NaN squared distance propagated as the unpruned kernel propagates it (numpy's min)."""
    out = []
    for q in p.tolist():
        best = math.inf
        for a, b in zip(poly[:-1].tolist(), poly[1:].tolist()):
            ab = [b[k] - a[k] for k in range(3)]
            ab2 = (ab[0] * ab[0] + ab[2] * ab[2]) + ab[1] * ab[1]
            inv = 1.0 / ab2 if ab2 > 0.0 else 0.0
            ap = [q[k] - a[k] for k in range(3)]
            u = ((ap[0] * ab[0] + ap[2] * ab[2]) + ap[1] * ab[1]) * inv
            u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
            d = [ap[k] - u * ab[k] for k in range(3)]
            dd = (d[0] * d[0] + d[2] * d[2]) + d[1] * d[1]
            if math.isnan(dd):
                best = math.nan
                break
            best = min(best, dd)
        out.append(math.sqrt(best))
    return np.array(out)


def _einsum_sums_lane_two_first() -> bool:
    """Whether this CPU's numpy sums a 3-term einsum as (x0 + x2) + x1 (AVX2, AVX-512)."""
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(4096, 3)), rng.normal(size=(4096, 3))
    x = a * b
    return bool(np.array_equal(np.einsum("ij,ij->i", a, b), (x[:, 0] + x[:, 2]) + x[:, 1]))


def _random_path(rng, n_vertices: int, scale: float) -> np.ndarray:
    poly = np.cumsum(rng.normal(size=(n_vertices, 3)) * scale, axis=0)
    if n_vertices > 3:  # repeated vertices: zero-length segments
        poly[n_vertices // 2] = poly[n_vertices // 2 - 1]
    return poly


def test_the_kernel_is_the_python_order_bit_for_bit():
    rng = np.random.default_rng(1)
    for trial in range(40):
        poly = _random_path(rng, int(rng.integers(2, 30)), 10.0 ** rng.uniform(-3, 2))
        p = rng.normal(size=(int(rng.integers(1, 40)), 3)) * 10.0 ** rng.uniform(-2, 2)
        assert np.array_equal(polyline_distances_m(p, poly), _python_distances(p, poly)), trial


@pytest.mark.skipif(not _einsum_sums_lane_two_first(),
                    reason="numpy's einsum sums in another order on this CPU (no AVX2)")
def test_the_kernel_gives_the_numpy_forms_bits():
    rng = np.random.default_rng(2)
    for trial in range(300):
        poly = _random_path(rng, int(rng.integers(2, 250)), 10.0 ** rng.uniform(-3, 2))
        p = poly[rng.integers(0, poly.shape[0], 200)] + rng.normal(size=(200, 3)) * 10.0 ** (
            rng.uniform(-4, 1))
        assert np.array_equal(polyline_distances_m(p, poly), _numpy_distances(p, poly)), trial


@pytest.mark.skipif(not _einsum_sums_lane_two_first(),
                    reason="numpy's einsum sums in another order on this CPU (no AVX2)")
def test_path_deviation_of_a_flown_square_is_the_numpy_forms():
    """A 60 s square, as the summary measures it: mean and max the old bits."""
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.reference.trajectories import make_trajectory
    from ardrone_nmpc.runs.memory import MemoryRecorder
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    cfg = load_config("configs/square.yaml", ["duration_s=20"])
    rec = MemoryRecorder()
    run_lockstep(cfg, recorder=rec)
    cols = rec.columns()
    xyz = np.column_stack([cols["x_true_m"], cols["y_true_m"], cols["z_true_m"]])
    xyz = xyz[np.all(np.isfinite(xyz), axis=1)]
    poly = make_trajectory(cfg.reference, duration_s=cfg.duration_s).polyline_m()
    d = _numpy_distances(xyz, poly)
    assert path_deviation(xyz, poly) == (float(d.mean()), float(d.max()))


def test_the_pruning_skips_no_segment_that_could_be_the_nearest():
    """Long paths (many chunks of CHUNK_SEGMENTS), positions on, near and far from them, at
    every scale: the bits of every segment measured (the Python order)."""
    from ardrone_nmpc.runs.path_kernels import CHUNK_SEGMENTS

    rng = np.random.default_rng(3)
    for trial in range(12):
        n = int(rng.integers(CHUNK_SEGMENTS - 1, 8 * CHUNK_SEGMENTS + 3))
        poly = _random_path(rng, n, 10.0 ** rng.uniform(-3, 2))
        p = poly[rng.integers(0, n, 60)] + rng.normal(size=(60, 3)) * 10.0 ** rng.uniform(-9, 1)
        assert np.array_equal(polyline_distances_m(p, poly), _python_distances(p, poly)), trial


def test_a_position_or_vertex_not_finite_gives_nan_as_unpruned():
    rng = np.random.default_rng(4)
    poly = _random_path(rng, 100, 1.0)
    p = poly[rng.integers(0, 100, 30)] + rng.normal(size=(30, 3)) * 0.01
    p[7] = [math.nan, 0.0, 0.0]
    d = polyline_distances_m(p, poly)
    assert np.isnan(d[7]) and np.isfinite(np.delete(d, 7)).all()
    for bad in (math.nan, math.inf, -math.inf):
        broken = poly.copy()
        broken[int(rng.integers(0, 100)), int(rng.integers(0, 3))] = bad
        assert np.isnan(polyline_distances_m(p, broken)).all(), bad  # every position's


def test_a_finite_path_whose_far_segment_measures_nan_gives_nan_as_unpruned():
    """Finite vertices and positions can still make a segment's squared distance NaN: a
    segment so short its 1/(ab·ab) overflows (u = 0·inf), or coordinates so large ab·ab or
    the dot product overflow (inf·0, inf − inf). Unpruned, the NaN is the answer; a box
    holding such a segment must not be skipped however far it is."""
    from ardrone_nmpc.runs.path_kernels import CHUNK_SEGMENTS

    near = [[0.0, 0.1 * i, 0.0] for i in range(CHUNK_SEGMENTS + 1)]
    p = np.array([[0.0, 0.5, 0.0], [0.0, 1.0, 0.0]])
    tiny = np.array(near + [[0.0, 101.0, 0.0], [1e-155, 101.0, 0.0], [0.0, 103.0, 0.0]])
    huge = np.array(near + [[1e200 * (1 + i), 1e200, 0.0] for i in range(4)])
    for poly in (tiny, huge):
        want = _python_distances(p, poly)
        assert np.isnan(want).all()
        assert np.array_equal(polyline_distances_m(p, poly), want, equal_nan=True)
    # a position far out (finite), near the path's first, huge vertices (distance 0) and far
    # from its small ones, whose dot products overflow to inf − inf: NaN, unpruned
    q = [1.7e308, 0.0, -1.7e308]
    mixed = np.array([q] * (CHUNK_SEGMENTS + 1) + [[float(i), 0.0, 0.0] for i in range(
        CHUNK_SEGMENTS)] + [[CHUNK_SEGMENTS + 2.0 * i, 0.0, 2.0 * i] for i in range(1, 8)])
    want = _python_distances(np.array([q]), mixed)
    assert np.isnan(want).all()
    assert np.array_equal(polyline_distances_m(np.array([q]), mixed), want, equal_nan=True)


def test_the_pruning_at_large_scales_and_thin_long_segments():
    """Paths of every scale up to 10¹², with long thin segments: the unpruned bits."""
    from ardrone_nmpc.runs.path_kernels import CHUNK_SEGMENTS

    rng = np.random.default_rng(5)
    for trial in range(30):
        n = int(rng.integers(2, 5 * CHUNK_SEGMENTS))
        scale = 10.0 ** rng.uniform(-3, 12)
        poly = _random_path(rng, n, scale) * np.array([1.0, 10.0 ** rng.uniform(-9, 0), 1.0])
        p = poly[rng.integers(0, n, 40)] + rng.normal(size=(40, 3)) * scale * 10.0 ** (
            rng.uniform(-12, 0))
        assert np.array_equal(polyline_distances_m(p, poly), _python_distances(p, poly),
                              equal_nan=True), trial
