"""P controller (eq. 4.16), command mapping (docs/design.md §4) and angle helpers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from ardrone_nmpc.core.angles import unwrap_near, wrap_angle_rad
from ardrone_nmpc.control.mapping import (
    DroneLimits,
    MappingError,
    PcmdCommand,
    map_to_pcmd,
    vz_reference_mps,
)
from ardrone_nmpc.control.proportional import PGains, p_control
from ardrone_nmpc.model import f
from ardrone_nmpc.core.types import AttitudeCommand

# Explicit gains: these tests check eq. 4.16's formulas, not the tuned defaults.
FORMULA_GAINS = PGains(k1_per_s=1.5, k2_rad_per_mps=0.35, k3_rad_per_mps=0.35, k4_per_s=2.0)

angles = st.floats(-math.pi, math.pi)


def state(x=0.0, vx=0.0, y=0.0, vy=0.0, z=0.0, vz=0.0, psi=0.0):
    return np.array([x, vx, y, vy, z, vz, psi])


def horizontal_accel(s, cmd):
    """(ẍ, ÿ) of model eq. 3.13 under the command's φ, θ with z̈ = 0."""
    xdot = f(s, [0.0, cmd.phi_rad, cmd.theta_rad, 0.0])
    return np.array([xdot[1], xdot[3]])


# ----------------------------------------------------------------------------- P controller
class TestPControlSigns:
    @given(
        angles,
        st.floats(0.05, 3.0),
        st.floats(-math.pi, math.pi),
        st.floats(-5, 5),
        st.floats(-5, 5),
    )
    def test_accelerates_towards_the_target(self, psi, dist, bearing, x0, y0):
        # Error magnitude ≤ 3 m keeps k·e ≤ 1.05 rad, inside tan's monotone branch.
        err = dist * np.array([math.cos(bearing), math.sin(bearing)])
        s = state(x=x0, y=y0, z=1.0, psi=psi)
        ref = state(x=x0 + err[0], y=y0 + err[1], z=1.0, psi=psi)
        acc = horizontal_accel(s, p_control(s, ref))
        assert acc @ err > 0.0
        # With k2 = k3 the push is along the error (exact to first order in the angles).
        cos_angle = acc @ err / (np.linalg.norm(acc) * dist)
        assert cos_angle > 0.9

    @given(angles, st.floats(0.05, 3.0), st.floats(-math.pi, math.pi), st.floats(0.5, 2.0))
    def test_unequal_gains_still_push_towards_target(self, psi, dist, bearing, ratio):
        gains = PGains(k2_rad_per_mps=0.3 * ratio, k3_rad_per_mps=0.3)
        err = dist * np.array([math.cos(bearing), math.sin(bearing)])
        s = state(psi=psi)
        ref = state(x=err[0], y=err[1], psi=psi)
        cmd = p_control(s, ref, gains)
        # eq. 3.13 means something only for tilts inside ±π/2 (tan changes sign beyond):
        # the unclipped P output can leave that range for large errors (hypothesis found one)
        assume(max(abs(cmd.phi_rad), abs(cmd.theta_rad)) < 1.4)
        assert horizontal_accel(s, cmd) @ err > 0.0

    @given(angles, st.floats(0.05, 2.5), st.floats(-math.pi, math.pi))
    def test_damps_velocity_at_the_target(self, psi, speed, heading):
        vel = speed * np.array([math.cos(heading), math.sin(heading)])
        s = state(x=1.0, vx=vel[0], y=-2.0, vy=vel[1], psi=psi)
        ref = state(x=1.0, y=-2.0, psi=psi)
        assert horizontal_accel(s, p_control(s, ref)) @ vel < 0.0

    def test_formulas_at_zero_heading(self):
        g = PGains(k1_per_s=1.1, k2_rad_per_mps=0.2, k3_rad_per_mps=0.4, k4_per_s=3.0)
        s = state(x=1.0, vx=0.5, y=2.0, vy=-0.25, z=0.4, vz=9.0, psi=0.0)
        ref = state(x=2.0, vx=7.0, y=1.0, vy=7.0, z=1.0, psi=0.3)  # ref velocities unused
        cmd = p_control(s, ref, g)
        assert cmd.vz_ref_mps == pytest.approx(1.1 * 0.6)
        assert cmd.theta_rad == pytest.approx(0.4 * (1.0 - 0.5))
        assert cmd.phi_rad == pytest.approx(-0.2 * (-1.0 + 0.25))
        assert cmd.psirate_radps == pytest.approx(3.0 * 0.3)

    def test_body_frame_rotation_at_quarter_turn(self):
        # Facing +y (ψ = π/2): a +y error is straight ahead (pitch), a +x error is to the right.
        s = state(psi=math.pi / 2)
        ahead = p_control(s, state(y=1.0, psi=math.pi / 2), FORMULA_GAINS)
        assert ahead.theta_rad == pytest.approx(0.35)
        assert ahead.phi_rad == pytest.approx(0.0, abs=1e-15)
        right = p_control(s, state(x=1.0, psi=math.pi / 2), FORMULA_GAINS)
        assert right.phi_rad == pytest.approx(0.35)
        assert right.theta_rad == pytest.approx(0.0, abs=1e-15)

    @given(st.floats(-3, 3), st.floats(-3, 3))
    def test_vz_reference_sign(self, z, z_d):
        vz_ref = p_control(state(z=z), state(z=z_d), FORMULA_GAINS).vz_ref_mps
        assert vz_ref == pytest.approx(1.5 * (z_d - z))
        if z_d > z:
            assert vz_ref > 0.0  # below the target: climb (z is up)
        elif z_d < z:
            assert vz_ref < 0.0

    def test_yaw_takes_short_way_across_pi(self):
        cmd = p_control(state(psi=3.0), state(psi=-3.0), FORMULA_GAINS)
        assert cmd.psirate_radps == pytest.approx(2.0 * (2 * math.pi - 6.0))
        assert cmd.psirate_radps > 0.0
        assert p_control(state(psi=-3.0), state(psi=3.0), FORMULA_GAINS).psirate_radps < 0.0

    @given(angles, angles)
    def test_yaw_error_never_exceeds_half_turn(self, psi, psi_d):
        rate = p_control(state(psi=psi), state(psi=psi_d), FORMULA_GAINS).psirate_radps
        assert abs(rate) <= 2.0 * math.pi + 1e-12
        # Integrating the rate for a short time reduces the wrapped heading error.
        err0 = abs(wrap_angle_rad(psi_d - psi))
        assume(1e-6 < err0 < math.pi - 1e-6)
        assert abs(wrap_angle_rad(psi_d - (psi + 1e-3 * rate))) < err0

    def test_not_clipped(self):
        cmd = p_control(state(), state(x=-1.5, z=1.0, psi=1.0), FORMULA_GAINS)
        assert abs(cmd.theta_rad) > 0.5 and cmd.psirate_radps == pytest.approx(2.0)

    @pytest.mark.parametrize("field", ["k1_per_s", "k2_rad_per_mps", "k3_rad_per_mps", "k4_per_s"])
    @pytest.mark.parametrize("bad", [0.0, -1.0, math.nan])
    def test_gains_validated(self, field, bad):
        with pytest.raises(ValueError, match=field):
            PGains(**{field: bad})


# ---------------------------------------------------------------------------------- mapping
LIM = DroneLimits(euler_angle_max_rad=0.2, control_vz_max_mps=0.7, control_yaw_radps=1.6)


class TestMapping:
    def test_formulas_and_signs(self):
        out = map_to_pcmd(AttitudeCommand(0.35, 0.1, 0.1, 0.8), LIM)
        assert out.roll_frac == pytest.approx(0.5)  # φ > 0 → roll right, positive
        assert out.pitch_frac == pytest.approx(-0.5)  # θ > 0 (forward) → nose down, negative
        assert out.gaz_frac == pytest.approx(0.5)
        assert out.yaw_frac == pytest.approx(-0.5)  # ψ̇ > 0 (CCW) → PCMD yaw < 0
        assert out.saturated == (False, False, False, False) and not out.any_saturated

    def test_defaults_are_sdk_values(self):
        lim = DroneLimits()
        assert (lim.euler_angle_max_rad, lim.control_vz_max_mps, lim.control_yaw_radps) == (
            0.2094, 0.7, 1.745)
        assert map_to_pcmd(AttitudeCommand(0.0, 0.0, 0.2094, 0.0)).pitch_frac == pytest.approx(-1.0)

    def test_saturation_clipped_and_flagged(self):
        out = map_to_pcmd(AttitudeCommand(-2.0, 0.05, 0.5, 0.0), LIM)
        assert out.pitch_frac == -1.0
        assert out.gaz_frac == -1.0
        assert out.roll_frac == pytest.approx(0.25)
        assert out.saturated == (False, True, True, False) and out.any_saturated

    def test_exactly_full_scale_is_not_saturation(self):
        out = map_to_pcmd(AttitudeCommand(0.7, -0.2, 0.0, -1.6), LIM)
        assert (out.roll_frac, out.gaz_frac, out.yaw_frac) == (-1.0, 1.0, 1.0)
        assert not out.any_saturated

    @given(st.floats(-5, 5), st.floats(-2, 2), st.floats(-2, 2), st.floats(-10, 10))
    def test_fractions_bounded_and_flags_honest(self, vz, phi, theta, rate):
        out = map_to_pcmd(AttitudeCommand(vz, phi, theta, rate), LIM)
        raw = (phi / 0.2, -theta / 0.2, vz / 0.7, -rate / 1.6)
        got = (out.roll_frac, out.pitch_frac, out.gaz_frac, out.yaw_frac)
        for r, g, sat in zip(raw, got, out.saturated):
            assert -1.0 <= g <= 1.0
            assert sat == (abs(r) > 1.0)
            assert g == (math.copysign(1.0, r) if sat else pytest.approx(r))

    @pytest.mark.parametrize("field", ["vz_ref_mps", "phi_rad", "theta_rad", "psirate_radps"])
    @pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
    def test_non_finite_refused(self, field, bad):
        values = dict(vz_ref_mps=0.1, phi_rad=0.0, theta_rad=0.0, psirate_radps=0.0)
        values[field] = bad
        with pytest.raises(MappingError, match=field):
            map_to_pcmd(AttitudeCommand(**values), LIM)

    def test_limits_validated(self):
        with pytest.raises(ValueError, match="control_vz_max_mps"):
            DroneLimits(control_vz_max_mps=0.0)

    def test_pcmd_any_saturated(self):
        assert PcmdCommand(0, 0, 0, 0, (False, False, False, True)).any_saturated

    def test_vz_reference(self):
        assert vz_reference_mps(0.2, 1.0, 0.065) == pytest.approx(0.265)
        assert vz_reference_mps(-0.1, -2.0, 0.5) == pytest.approx(-1.1)
        with pytest.raises(MappingError, match="zacc_mps2"):
            vz_reference_mps(0.0, math.nan, 0.065)
        with pytest.raises(MappingError, match="vz_est_mps"):
            vz_reference_mps(math.inf, 0.0, 0.065)
        with pytest.raises(MappingError, match="dt_s"):
            vz_reference_mps(0.0, 0.0, -0.065)


# ----------------------------------------------------------------------------------- angles
class TestAngles:
    @given(st.floats(-1e6, 1e6))
    def test_wrap_properties(self, a):
        w = wrap_angle_rad(a)
        assert isinstance(w, float)
        assert -math.pi < w <= math.pi
        assert wrap_angle_rad(w) == w
        tol = 1e-15 * max(1.0, abs(a)) + 1e-15
        assert math.sin(w) == pytest.approx(math.sin(a), abs=tol * 10)
        assert math.cos(w) == pytest.approx(math.cos(a), abs=tol * 10)

    @given(st.floats(-math.pi, math.pi, exclude_min=True))
    def test_wrap_is_identity_inside_range(self, a):
        assert wrap_angle_rad(a) == a

    def test_wrap_endpoints(self):
        assert wrap_angle_rad(math.pi) == math.pi
        assert wrap_angle_rad(-math.pi) == math.pi
        assert wrap_angle_rad(2 * math.pi) == 0.0
        assert wrap_angle_rad(1.5 * math.pi) == pytest.approx(-0.5 * math.pi)
        assert math.isnan(wrap_angle_rad(math.nan))
        assert math.isnan(wrap_angle_rad(math.inf))

    def test_wrap_array(self):
        a = np.array([[0.0, -math.pi, 7.0], [-7.0, 3 * math.pi / 2, math.nan]])
        w = wrap_angle_rad(a)
        assert w.shape == a.shape
        expected = [wrap_angle_rad(v) for v in a[:, :2].ravel()]
        np.testing.assert_array_equal(w[:, :2].ravel(), expected)
        assert w[0, 2] == wrap_angle_rad(7.0) and math.isnan(w[1, 2])

    @given(st.floats(-100, 100), st.floats(-100, 100))
    def test_unwrap_near(self, angle, ref):
        u = unwrap_near(angle, ref)
        assert -math.pi - 1e-12 < u - ref <= math.pi + 1e-12
        k = (u - angle) / (2 * math.pi)
        assert k == pytest.approx(round(k), abs=1e-9)

    def test_unwrap_near_across_seam(self):
        assert unwrap_near(-3.0, 3.0) == pytest.approx(2 * math.pi - 3.0)
        assert unwrap_near(0.1, 4 * math.pi) == pytest.approx(4 * math.pi + 0.1)


def test_mapping_never_emits_negative_zero():
    out = map_to_pcmd(AttitudeCommand(-0.0, -0.0, 0.0, 0.0), LIM)
    for frac in (out.roll_frac, out.pitch_frac, out.gaz_frac, out.yaw_frac):
        assert math.copysign(1.0, frac) == 1.0
