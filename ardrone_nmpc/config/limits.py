"""Bounds of every setting that becomes a count, an allocation or a coordinate.

A validated config must not crash later: a duration of 1e308 s is an infinite tick count, a
waypoint at 1e8 m a path sampled into 37 GiB. The schema (:mod:`ardrone_nmpc.config.schema`)
and the waypoint reader (:mod:`ardrone_nmpc.reference.waypoints`) both check against these
numbers, so ``check`` rejects what a run would fail on, before a run directory exists.
"""

from __future__ import annotations

#: Longest experiment, settle phase, step time, square leg or ellipse lap (s): an hour,
#: five times what an AR.Drone battery flies (≈ 12 min). At the shortest control period
#: (1 ms) that is 3.6 million log rows.
MAX_SPAN_S = 3600.0

#: Shortest square leg or ellipse lap (s): the reference speed (size / time) stays finite.
MIN_SPAN_S = 1e-3

#: Largest coordinate or path size (m) anywhere in a config or a waypoint file: a kilometre
#: is beyond any motion-capture volume, and paths are sampled every 2 cm for the deviation
#: metrics.
MAX_COORDINATE_M = 1000.0

#: Longest waypoint path (m, summed over its segments), so its 2 cm polyline stays below
#: half a million points (12 MB); the largest built-in path (a 1000 m ellipse) is 6.3 km.
MAX_PATH_LENGTH_M = 10_000.0

#: Most waypoints (data rows) in a path file.
MAX_WAYPOINTS = 10_000

#: Largest path file (bytes) read at all: far above MAX_WAYPOINTS rows with comments.
MAX_PATH_FILE_BYTES = 16 * 1024 * 1024

#: Smallest time step between consecutive waypoints (s): the segment velocities stay finite.
MIN_WAYPOINT_STEP_S = 1e-3

#: Longest experiment name (characters, ASCII). A run directory is named
#: ``<YYYYmmdd-HHMMSS>-<name>[-rerun][-<n>]``; one path component holds 255 bytes on every
#: common file system (ext4, XFS, Btrfs, APFS, NTFS, FAT long names): 16 + 200 + 6 leaves
#: 33 bytes for the collision number.
MAX_NAME_CHARS = 200

#: Suffix ``replay --rerun`` appends to the experiment name (counted in MAX_NAME_CHARS's
#: budget above).
RERUN_SUFFIX = "-rerun"

#: Longest Lorenz-system time a 'lorenz' path is integrated over (lorenz_time_scale ×
#: duration_s, dimensionless): ≈ 2 s and 60 MB to build; the configs use 6.
MAX_LORENZ_TIME = 200.0

#: The bound of a command under ``drone.command_convention: kit`` (and of the tilt limit in
#: its units): the Simulink kit's ports saturate at ±1.
KIT_PORT_LIMIT = 1.0

#: The firmware's cap of ``control:euler_angle_max`` (rad), the largest tilt a real drone flies:
#: the protocol's range (``protocol.config_text.EULER_ANGLE_MAX_LIMIT_RAD``, equal by a test),
#: here for the schema, which imports no protocol.
FIRMWARE_TILT_MAX_RAD = 0.52
