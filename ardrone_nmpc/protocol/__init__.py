"""Pure byte encoders and decoders of the three wire formats the tool speaks.

* :mod:`ardrone_nmpc.protocol.at` — AR.Drone 2.0 AT commands (UDP 5556, ASCII): command records,
  the encoder, :class:`~ardrone_nmpc.protocol.at.AtSequencer` (numbering from 1, packing into
  datagrams of at most 1024 bytes) and the inverse parser used by the simulator
  (docs/protocol.md §2).
* :mod:`ardrone_nmpc.protocol.navdata` — AR.Drone navdata (UDP 5554, binary): header, state bits,
  option walking, the demo option with unit-converted views, the checksum option (§4).
* :mod:`ardrone_nmpc.protocol.mocap` — the Vicon-style UDP object stream (docs/mocap-stream.md):
  frame number and pose items, millimetres/radians on the wire, metres/radians in the records.

Layering (docs/design.md §3): nothing here opens a socket or reads a clock, and nothing imports
``links``, ``sim``, ``control`` or ``estimation``. Every decoder raises only its own error type
(:class:`~ardrone_nmpc.protocol.at.AtParseError`,
:class:`~ardrone_nmpc.protocol.navdata.NavdataError`,
:class:`~ardrone_nmpc.protocol.mocap.MocapError`, all subclasses of :class:`ValueError`) on
malformed input, never ``IndexError``, ``struct.error`` or ``UnicodeDecodeError``.
All binary data is little-endian; every ``struct`` format carries the ``<`` prefix.
"""
