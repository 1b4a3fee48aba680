"""ardrone-nmpc: fast nonlinear MPC flight experiments for the Parrot AR.Drone 2.0."""

from ardrone_nmpc.core.numerics import pin_numba_target as _pin_numba_target

__version__ = "0.1.0"

_pin_numba_target()  # before any kernel compiles: the same bits on every x86-64 machine
