"""Small shared records and the named indices of the state and input vectors.

State ``x = [x, ẋ, y, ẏ, z, ż, ψ]`` (m, m/s, m, m/s, m, m/s, rad) and input
``u = [z̈, φ, θ, ψ̇]`` (m/s², rad, rad, rad/s), exactly as thesis eq. 3.10–3.11.
"""

from __future__ import annotations

from dataclasses import dataclass

# State indices (thesis x1..x7, zero-based).
IX_X, IX_VX, IX_Y, IX_VY, IX_Z, IX_VZ, IX_PSI = range(7)
STATE_DIM = 7
STATE_NAMES = ("x_m", "vx_mps", "y_m", "vy_mps", "z_m", "vz_mps", "psi_rad")

# Input indices (thesis u1..u4, zero-based).
IU_ZACC, IU_PHI, IU_THETA, IU_PSIRATE = range(4)
INPUT_DIM = 4
INPUT_NAMES = ("u_zacc_mps2", "u_phi_rad", "u_theta_rad", "u_psirate_radps")

GRAVITY_MPS2 = 9.81


@dataclass(frozen=True, slots=True)
class AttitudeCommand:
    """What a high-level controller asks of the drone's inner loops for one tick.

    Attributes
    ----------
    vz_ref_mps : vertical-speed reference (m/s), up positive.
    phi_rad : roll reference (rad); positive accelerates towards −y at ψ = 0.
    theta_rad : pitch reference (rad); positive accelerates towards +x at ψ = 0.
    psirate_radps : yaw-rate reference (rad/s), counter-clockwise seen from above.
    """

    vz_ref_mps: float
    phi_rad: float
    theta_rad: float
    psirate_radps: float
