"""Network links to the drone and the motion-capture system (docs/design.md §2–§3).

* :mod:`ardrone_nmpc.links.udp` — socket helper (:func:`~ardrone_nmpc.links.udp.open_udp`), the
  :class:`~ardrone_nmpc.links.udp.Clock` protocol and :class:`~ardrone_nmpc.links.udp.LinkStats`
  (packets, sliding-window rate, loss from sequence gaps, malformed count, age).
* :mod:`ardrone_nmpc.links.drone_link` — :class:`~ardrone_nmpc.links.drone_link.DroneLink`: the
  AR.Drone 2.0 AT-command sender (one sequencer, keepalive thread resending REF + PCMD every
  30 ms, hover on a stale controller command) and navdata receiver (wake-up, bootstrap exit,
  re-wake after 0.2 s of silence, a drone airborne at connect refused); with
  :mod:`~ardrone_nmpc.links.drone_commands` (REF commands, the take-off guard that drops the
  take-off bit when the drone lands by itself) and :mod:`~ardrone_nmpc.links.drone_config`
  (the config ACK handshake, the read-back over TCP 5559 and its check).
* :mod:`ardrone_nmpc.links.mocap_source` — :class:`~ardrone_nmpc.links.mocap_source.MocapSource`:
  the one interface of every mocap source (freshness rules, readings);
  :func:`~ardrone_nmpc.links.mocap_factory.open_mocap_source` opens the one ``mocap.kind`` names.
* :mod:`ardrone_nmpc.links.mocap_link` — :class:`~ardrone_nmpc.links.mocap_link.MocapLink`: the
  latest fresh pose of one object from the Vicon-style UDP stream, receipt-stamped, from one
  sender (others are counted, reported and ignored).
* :mod:`ardrone_nmpc.links.motioncapture_source` —
  :class:`~ardrone_nmpc.links.motioncapture_source.MotionCaptureSource`: the same from any
  libmotioncapture system (Vicon SDK, OptiTrack, Qualisys, VRPN, …), run in a child process.
* :mod:`ardrone_nmpc.links.flight_lock` — one flight per drone address on this machine.

Layering: links own sockets, threads and clocks; every byte is encoded or decoded by
:mod:`ardrone_nmpc.protocol` (the plain-text configuration dump of TCP 5559 included:
:mod:`~ardrone_nmpc.protocol.config_text`).
Protocol records are converted into :mod:`ardrone_nmpc.core.types` records (``NavdataSample``,
``MocapPose``) at this boundary. Links never decide flight policy: closing a link stops its
threads and closes its sockets, it does not land the drone — the session does that.
"""

from ardrone_nmpc.links.udp import Clock, LinkStats, open_udp

__all__ = ["Clock", "LinkStats", "open_udp"]
