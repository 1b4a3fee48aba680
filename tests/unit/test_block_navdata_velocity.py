"""A block of ticks rotates the navdata's body speeds to world ẋ, ẏ
(``runtime/lockstep_block._navdata_velocity_world``) to the bits the Python stages' rotation
gives (``runtime/estimate.navdata_velocity_world``, whose numbers the per-tick path hands the
compiled call): headings all round and beyond, speeds of every size and sign, −0.0."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.runtime.estimate import navdata_velocity_world
from ardrone_nmpc.runtime.lockstep_block import _navdata_velocity_world
from ardrone_nmpc.sim import drone_block as db

rotate = callable_from_python(_navdata_velocity_world)


def test_the_blocks_rotation_is_the_python_ones_bit_for_bit():
    rng = np.random.default_rng(5)
    psi = np.concatenate([rng.uniform(-4.0, 4.0, 4000), rng.uniform(-1e3, 1e3, 500),
                          [0.0, -0.0, math.pi, -math.pi / 2, 1e-300]])
    speeds = np.concatenate([rng.normal(0.0, 0.5, (psi.size - 3, 2)),
                             [[-0.0, 0.0], [1e-9, -3.0], [0.0, -0.0]]])
    d = np.zeros(db.D_SIZE)
    for p, (fwd, right) in zip(psi, speeds):
        d[db.D_PSI], d[db.D_NAV_VX], d[db.D_NAV_VY] = p, fwd, right
        nav = SimpleNamespace(vx_body_mps=np.float64(fwd), vy_body_mps=np.float64(right))
        want = navdata_velocity_world(nav, float(p))
        got = rotate(d)
        assert np.array(got).tobytes() == np.array(want, dtype=np.float64).tobytes(), (p, fwd)
