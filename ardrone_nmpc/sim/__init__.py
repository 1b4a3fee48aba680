"""Loopback simulation of the AR.Drone 2.0 and the motion-capture system.

* :mod:`ardrone_nmpc.sim.plant` — the drone *with its on-board controller* as the ground station
  sees it (docs/plant.md): PCMD fractions in, delayed first-order tilt / yaw-rate / vertical-speed
  loops, drag, take-off / landing / emergency, battery, and seeded mocap and navdata sensors.
* ``drone_server`` / ``mocap_server`` (AT commands and navdata, the pose stream over UDP) serve
  that plant on 127.0.0.1; the drone's behaviour is ``drone_firmware`` (AT commands, watchdogs,
  navdata status), ``drone_config`` (its configuration) and ``control_port`` (TCP 5559).
* ``sensors`` — the lockstep runner's sensor datagrams; both drones encode navdata with
  :func:`ardrone_nmpc.protocol.navdata.encode_drone_navdata`.

Layering: ``sim`` never imports ``ardrone_nmpc.control`` or ``ardrone_nmpc.estimation``; the
plant is not the NMPC's prediction model.
"""
