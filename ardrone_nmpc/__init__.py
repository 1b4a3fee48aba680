"""ardrone-nmpc: fast nonlinear MPC flight experiments for the Parrot AR.Drone 2.0."""

__version__ = "0.1.0"
