"""``wrap_angle_rad`` of an array: the element-wise wrap of each element, bit for bit (the
array path copies the elements already in (−π, π] and wraps only the others)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.core import angles

SPECIALS = [math.pi, -math.pi, np.nextafter(math.pi, 4.0), np.nextafter(-math.pi, -4.0), 0.0,
            -0.0, math.nan, -math.nan, math.inf, -math.inf, 3.0 * math.pi, -3.0 * math.pi,
            1e300, 5e-324, 2.0 * math.pi, -2.0 * math.pi]


def _each(a) -> np.ndarray:
    """The scalar wrap applied to each element: what the array path must give."""
    a = np.asarray(a, dtype=float)
    return np.array([angles._wrap_scalar(float(v)) for v in a.ravel()],
                    dtype=float).reshape(a.shape)


@pytest.mark.parametrize("seed", range(20))
def test_the_array_wrap_is_the_scalar_wrap_of_each_element(seed):
    rng = np.random.default_rng(seed)
    a = np.concatenate([rng.normal(0.0, 1.0 + seed, rng.integers(0, 60)),
                        rng.choice(SPECIALS, rng.integers(0, 12))])
    rng.shuffle(a)
    if seed % 2 and a.size % 2 == 0:
        a = a.reshape(-1, 2)
    with np.errstate(all="raise"):  # no floating-point warning either
        got = angles.wrap_angle_rad(a)
    want = _each(a)
    assert got.shape == want.shape and got.dtype == np.float64
    assert got.tobytes() == want.tobytes()


def test_the_array_wrap_leaves_its_input_alone():
    a = np.array([4.0, -0.5, math.nan])
    before = a.tobytes()
    out = angles.wrap_angle_rad(a)
    assert a.tobytes() == before and out is not a
    assert angles.wrap_angle_rad([0.5, 7.0]).tolist() == [0.5, 7.0 - 2.0 * math.pi]
