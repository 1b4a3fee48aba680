"""Flight commands of the drone link: REF levels and edges, flat trim, and the take-off guard.

docs/protocol.md §2.4. Split from :mod:`ardrone_nmpc.links.drone_link` by concept:
:class:`FlightCommands` is the part of :class:`~ardrone_nmpc.links.drone_link.DroneLink` that
decides which ``AT*REF`` the keepalive holds (it uses the link's locks, sequencer and navdata
state). Bit 9 is a level (take-off while 1, land while 0); bit 8 acts on its rising edge.

The take-off guard: once the link lands or cuts the drone, or the drone — held in take-off —
lands or cuts by itself, the take-off bit is dropped at once and never sent again by this link
(:attr:`FlightCommands.takeoff_barred`). The receiver thread checks every navdata packet
(:meth:`FlightCommands._watch_takeoff`): touch-down (state bit 0 fell after it had risen), an
emergency (bit 31), or — after flight (ctrl_state major 3/4) — a landing transition (major 8
in the SDK's numbering, 9 in firmware 2.4's). Holding bit 9 through a landing the drone decided
itself would launch it again right after touch-down.
"""

from __future__ import annotations

from ardrone_nmpc.links.drone_config import LinkError, check_positive as _check_positive
from ardrone_nmpc.protocol.at import Ftrim, Pcmd, Ref
from ardrone_nmpc.protocol.navdata import CtrlMajor, DroneState, Navdata

__all__ = ["FlightCommands", "TakeoffGuard"]

_HOVER = Pcmd.hover()
_FLYING_MAJORS = (int(CtrlMajor.FLYING), int(CtrlMajor.HOVERING))
# landing in the SDK header (8) and in firmware 2.4 (9); either, after flight, means "going down"
_SELF_LANDING_MAJORS = (int(CtrlMajor.TRANS_LANDING), int(CtrlMajor.TRANS_LOOPING))


class TakeoffGuard:
    """The one detection of a drone that lands or cuts its motors by itself while held in
    take-off (module doc): fed each navdata packet's state bits and ctrl_state major, it says
    what the drone showed — every client of a drone (this link, the lockstep simulation's)
    asks it."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """A new take-off: nothing seen yet."""
        self.seen_airborne = False   # since take-off: state bit 0 seen set
        self.seen_flying = False     # since take-off: ctrl_state major 3/4 seen

    def observe(self, state: DroneState, ctrl_major: int | None) -> str | None:
        """What the drone did by itself, as ``"the drone <what>"`` completes it, or None."""
        airborne = DroneState.FLY in state
        self.seen_airborne |= airborne
        self.seen_flying |= airborne and ctrl_major in _FLYING_MAJORS
        if DroneState.EMERGENCY in state:
            return "reported an emergency (state bit 31: motors cut)"
        if self.seen_airborne and not airborne:
            return "touched down (state bit 0 cleared)"
        if self.seen_flying and ctrl_major in _SELF_LANDING_MAJORS:
            return f"began to land (ctrl_state major {ctrl_major})"
        return None


class FlightCommands:
    """REF commands and the take-off guard of :class:`~ardrone_nmpc.links.drone_link.DroneLink`
    (a mixin: it needs the link's ``_at_lock``, ``_ref``, ``_state``, ``_stop``,
    ``_nav_cond``, ``_nav_index``, the send helpers and ``_await_state``)."""


    @property
    def takeoff_barred(self) -> str | None:
        """Why the take-off bit will never be sent again on this link (None: it may be)."""
        return self._takeoff_barred

    @property
    def self_landing(self) -> str | None:
        """What the drone showed when it landed or cut its motors by itself while held in
        take-off (None unless it did); the link dropped the take-off bit at that packet."""
        return self._self_landing

    def takeoff(self) -> None:
        """Hold REF take-off (bit 9 = 1) from now on; the command is reset to hover. Refused
        (LinkError) in emergency and once :attr:`takeoff_barred`."""
        with self._at_lock:
            self._require_open()
            if self._takeoff_barred is not None:
                raise LinkError(f"take-off refused: {self._takeoff_barred}")
            if self._state is not None and DroneState.EMERGENCY in self._state:
                raise LinkError("take-off refused: the drone is in emergency (state bit 31); "
                                "call reset_emergency() on the ground first")
            self._guard.reset()
            self._ref = Ref.takeoff()
            self._set_pcmd_locked(_HOVER, None)
            self._send_current_locked(raise_errors=True)

    def land(self) -> None:
        """Hold REF land (bit 9 = 0) from now on (and never take-off again on this link); the
        command is reset to hover."""
        with self._at_lock:
            self._require_open()
            self._hold_ref_locked(Ref.landing(), "the link landed the drone")
            self._send_current_locked(raise_errors=True)

    def emergency(self) -> None:
        """Cut the motors: hold REF with bit 8 (its rising edge acts) and bit 9 = 0. If this
        link has sent no REF yet, one with bit 8 low goes first in the same datagram (bit 9 as
        the drone's state bit 0, so it changes nothing), so the drone sees the edge whatever the
        previous client left."""
        with self._at_lock:
            self._require_open()
            first = self._ref is None
            self._hold_ref_locked(Ref.emergency(), "the link cut the motors")
            bodies = self._current_bodies_locked(self._clock(), count=False)
            if first:
                flying = self._state is not None and DroneState.FLY in self._state
                bodies.insert(0, Ref.takeoff() if flying else Ref.landing())
            self._send_locked(bodies, raise_errors=True)

    def _hold_ref_locked(self, ref: Ref, why: str) -> None:
        self._ref = ref
        if self._takeoff_barred is None:
            self._takeoff_barred = why
        self._set_pcmd_locked(_HOVER, None)

    def reset_emergency(self, timeout_s: float = 2.0) -> None:
        """Clear an emergency on the ground: REF bit 8 low for two keepalive periods, then high
        until navdata shows bit 31 cleared, then REF land. Refused unless the latest navdata
        shows the emergency bit (an edge on a drone *not* in emergency would cut its motors).
        Raises :class:`LinkError` if bit 31 is still set after ``timeout_s``.
        """
        timeout_s = _check_positive("timeout_s", timeout_s)
        state = self._state
        if state is None or DroneState.EMERGENCY not in state:
            raise LinkError("reset_emergency refused: navdata does not show an emergency")
        with self._at_lock:
            self._require_open()
            self._hold_ref_locked(Ref.landing(), "the link reset an emergency")
            self._send_current_locked(raise_errors=True)
        if self._stop.wait(2.0 * self.keepalive_interval_s):
            raise LinkError("link closed during reset_emergency")
        with self._nav_cond:
            index = self._nav_index
        try:
            with self._at_lock:
                self._require_open()
                self._ref = Ref.emergency()
                self._send_current_locked(raise_errors=True)
            if not self._await_state(lambda s: DroneState.EMERGENCY not in s, index, timeout_s):
                raise LinkError(f"emergency not cleared (state bit 31 still set after "
                                f"{timeout_s:.2f} s)")
        finally:
            with self._at_lock:
                self._ref = Ref.landing()
                if self._at_sock is not None:
                    self._send_current_locked(raise_errors=False)

    def flat_trim(self) -> None:
        """``AT*FTRIM``: current attitude = level. Only on the ground on a level surface;
        refused (LinkError) while navdata shows the drone flying."""
        with self._at_lock:
            self._require_open()
            if self._state is not None and DroneState.FLY in self._state:
                raise LinkError("flat trim refused: the drone is flying (state bit 0)")
            self._send_locked([Ftrim()], raise_errors=True)

    def _watch_takeoff(self, state: DroneState, packet: Navdata) -> None:
        """While REF take-off is held: drop it at once if the drone lands or cuts by itself
        (module doc). Runs in the receiver thread, one packet after the drone shows it."""
        ref = self._ref
        if ref is None or not ref.is_takeoff or ref.is_emergency:
            return
        what = self._guard.observe(state, packet.demo.ctrl_major
                                   if packet.demo is not None else None)
        if what is None:
            return
        ctrl = f"0x{packet.demo.ctrl_state:08x}" if packet.demo is not None else "none"
        with self._at_lock:
            if self._ref is not ref:       # the link changed REF meanwhile: not by itself
                return
            self._self_landing = f"the drone {what}; ctrl_state {ctrl}"
            self._hold_ref_locked(Ref.landing(), f"the drone landed by itself: {what}")
            if self._at_sock is not None:
                self._send_current_locked(raise_errors=False)

