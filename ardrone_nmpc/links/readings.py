"""What a drone link keeps of the newest navdata packets: :class:`PacketReadings`.

One home for the readings :class:`~ardrone_nmpc.links.drone_link.DroneLink` and
:class:`~ardrone_nmpc.links.operator_link.OperatorLink` share — the state word of any packet,
the flight mode it shows, the newest demo sample, each with its receipt time — so that a
landing reads either link the same way. Light on purpose (no numerical imports at load).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.core.types import FlightMode, NavdataSample
    from ardrone_nmpc.protocol.navdata import DroneState

__all__ = ["PacketReadings"]


class PacketReadings:
    """What a link keeps of the drone's newest navdata packets — the state word of any packet
    (bootstrap ones included), the flight mode it shows, and the newest demo sample — each with
    its receipt time. A mixin: the link calls :meth:`_init_readings` in its constructor and
    :meth:`_note_packet` under its lock for every packet it accepts. This is what a landing
    reads (:meth:`~ardrone_nmpc.runtime.session.FlightSession.land`)."""

    def _init_readings(self) -> None:
        self._state: DroneState | None = None
        self._state_rx_t_s = -math.inf
        self._packet_mode: FlightMode | None = None
        self._navdata: NavdataSample | None = None
        self._navdata_rx_t_s = -math.inf

    def _note_packet(self, state: DroneState, mode: FlightMode,
                     sample: NavdataSample | None, t_s: float) -> None:
        """A packet received at ``t_s``: its state word, the mode it shows
        (:func:`~ardrone_nmpc.links.drone_link.flight_mode_of`) and its demo sample, if any
        (:func:`~ardrone_nmpc.links.drone_link.navdata_sample_of`)."""
        self._state = state
        self._state_rx_t_s = t_s
        self._packet_mode = mode
        if sample is not None:
            self._navdata, self._navdata_rx_t_s = sample, t_s

    @property
    def navdata(self) -> NavdataSample | None:
        """The latest demo navdata sample (None before the first)."""
        return self._navdata

    @property
    def navdata_rx_t_s(self) -> float:
        """Receipt time (link clock) of :attr:`navdata`; −inf before the first."""
        return self._navdata_rx_t_s

    @property
    def state(self) -> DroneState | None:
        """State bits of the latest accepted navdata packet (bootstrap packets included)."""
        return self._state

    @property
    def state_rx_t_s(self) -> float:
        """Receipt time (link clock) of :attr:`state`: the latest accepted packet of any kind;
        −inf before the first."""
        return self._state_rx_t_s

    @property
    def packet_mode(self) -> FlightMode | None:
        """The flight mode the latest accepted packet shows (:func:`flight_mode_of`; a
        bootstrap packet has no ctrl_state, so state bit 0 alone decides); None before one."""
        return self._packet_mode
