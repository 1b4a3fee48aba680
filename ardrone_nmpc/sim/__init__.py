"""Loopback simulation of the AR.Drone 2.0 and the motion-capture system.

* :mod:`ardrone_nmpc.sim.plant` — the drone *with its on-board controller* as the ground station
  sees it (specs/plant.md): PCMD fractions in, delayed first-order tilt / yaw-rate / vertical-speed
  loops, drag, take-off / landing / emergency, battery, and seeded mocap and navdata sensors.
* ``drone_server`` / ``mocap_server`` (AT commands and navdata, the pose stream over UDP) serve
  that plant on 127.0.0.1.

Layering: ``sim`` never imports ``ardrone_nmpc.control`` or ``ardrone_nmpc.estimation``; the
plant is not the NMPC's prediction model.
"""
