"""The numbers of a nominal tick's row as a block of ticks writes them: one row of a float64
table a tick (``runtime/lockstep_block``'s kernel writes it; ``runs/log_columns.block_cells``
makes it the row's cells). Compiled code reads these indices: a kernel source
(``core/kernel_cache.KERNEL_SOURCES``).
"""

from __future__ import annotations

#: The row's numbers: the first 21 are the cells of ``t_s`` …
#: ``cmd_yaw_frac`` in column order; then the saturation bits, the solver's figures, the
#: feedback's ages, the navdata's battery, the tick's compute time, the pose's time, the
#: navdata's speeds and angles, the truth; the second mocap object's cells (``target_x_m`` …
#: ``target_age_ms``: a flight with one, ``runtime/second_object``); the navdata's state word
#: (through the wire: ``sim/wire_block``; NaN: a sample without one).
(BR_T, BR_X, BR_Y, BR_Z, BR_PSI, BR_VX, BR_VY, BR_VZ, BR_X_REF, BR_Y_REF, BR_Z_REF,
 BR_PSI_REF, BR_ZACC, BR_PHI, BR_THETA, BR_RATE, BR_VZ_REF, BR_ROLL, BR_PITCH, BR_GAZ, BR_YAW,
 BR_SATURATED, BR_SOLVE_US, BR_NORM, BR_GMRES, BR_NEWTON, BR_MOCAP_MS, BR_NAV_MS, BR_BATTERY,
 BR_COMPUTE_US, BR_MOCAP_T, BR_NAV_VX, BR_NAV_VY, BR_NAV_ROLL, BR_NAV_PITCH, BR_TRUE_X,
 BR_TRUE_Y, BR_TRUE_Z, BR_TRUE_PSI, BR_TRUE_VZ, BR_TARGET_X, BR_TARGET_Y, BR_TARGET_Z,
 BR_TARGET_PSI, BR_TARGET_T, BR_TARGET_AGE, BR_NAV_STATE) = range(47)
BLOCK_ROW = 47
