"""Open the mocap source a config names (``mocap.kind``): Vicon Tracker's UDP stream or a
libmotioncapture system, both behind :class:`~ardrone_nmpc.links.mocap_source.MocapSource`.

The factory lives apart from the base class so that the base imports neither source.
"""

from __future__ import annotations

import time

from ardrone_nmpc.links.mocap_source import MOCAP_KINDS, MocapSource
from ardrone_nmpc.links.udp import Clock

__all__ = ["open_mocap_source"]


def open_mocap_source(mocap_cfg, *, other_objects: tuple[str, ...] = (),
                      port: int | None = None, clock: Clock = time.monotonic) -> MocapSource:
    """The source ``mocap_cfg`` (a ``MocapConfig``) describes, not yet started.

    ``port`` overrides ``mocap.port`` (``fly --mocap-port``; UDP only). The ``motioncapture``
    library is imported only here, and only for that kind: a missing one raises
    :class:`MocapConnectError` naming the extra to install.
    """
    kind = mocap_cfg.kind
    if kind == "vicon_udp":
        from ardrone_nmpc.links.mocap_link import MocapLink

        return MocapLink(mocap_cfg.bind_host, port or mocap_cfg.port,
                         object_name=mocap_cfg.object_name, clock=clock,
                         other_objects=tuple(other_objects))
    if kind == "motioncapture":
        from ardrone_nmpc.links.motioncapture_source import MotionCaptureSource

        return MotionCaptureSource.from_config(mocap_cfg, other_objects=tuple(other_objects),
                                               clock=clock)
    raise ValueError(f"unknown mocap.kind {kind!r}; choose one of {', '.join(MOCAP_KINDS)}")
