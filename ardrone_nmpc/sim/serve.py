"""``ardrone-nmpc sim-drone``: the loopback drone and mocap streamer as a stand-alone process.

Serves the AR.Drone protocol (AT commands, navdata, the TCP configuration port) on a
loopback address and streams the simulated pose to a loopback target until interrupted
(Ctrl-C / SIGTERM), then stops every thread and closes every socket. Any AR.Drone client
pointed at the bind address (and a mocap receiver on the target port) flies it.
"""

from __future__ import annotations

import signal
import time
import threading
from typing import Callable, Optional

from ardrone_nmpc.protocol.config_text import CONTROL_PORT
from ardrone_nmpc.sim.addresses import require_loopback_host

__all__ = ["parse_host_port", "serve", "CONTROL_PORT"]



def parse_host_port(text, *, what: str = "address") -> tuple[str, int]:
    """``"127.0.0.1:51001"`` (or a ``(host, port)`` pair) → ``("127.0.0.1", 51001)``; the host
    must be a loopback address. Raises ValueError with a one-line message."""
    if isinstance(text, (tuple, list)):
        host, port = text
    else:
        host, sep, port = str(text).rpartition(":")
        if not sep or not host:
            raise ValueError(f"{what} {text!r}: expected host:port, e.g. 127.0.0.1:51001")
    try:
        port = int(port)
    except (TypeError, ValueError):
        raise ValueError(f"{what} {text!r}: port must be an integer") from None
    if not 1 <= port <= 65535:
        raise ValueError(f"{what} {text!r}: port must be in 1..65535")
    return require_loopback_host(host, what), port


def serve(*, cfg, bind: str = "127.0.0.1", at_port: int = 5556, navdata_port: int = 5554,
          mocap_to="127.0.0.1:51001", seed: Optional[int] = None,
          control_port: Optional[int] = CONTROL_PORT, echo: Callable[[str], None] = print,
          stop_event: Optional[threading.Event] = None) -> None:
    """Run the simulators until Ctrl-C (or ``stop_event`` is set); print what is served.
``control_port`` None serves no configuration port, 0 a free one.

    Raises ValueError (non-loopback ``bind`` or ``mocap_to``, bad ports) before opening any
    socket, and OSError if a port is taken.
    """
    from ardrone_nmpc.sim.loopback import start_loopback

    bind = require_loopback_host(bind, "--bind")
    mocap_host, mocap_port = parse_host_port(mocap_to, what="--mocap-to")
    for name, port in (("--at-port", at_port), ("--navdata-port", navdata_port),
                       ("--control-port", control_port)):
        if port is not None and not 0 <= int(port) <= 65535:
            raise ValueError(f"{name} {port}: must be in 0..65535")
    stop = stop_event if stop_event is not None else threading.Event()
    seed = cfg.sim.seed if seed is None else seed

    previous = None
    if threading.current_thread() is threading.main_thread():
        def _on_sigterm(signum, frame):  # pragma: no cover - exercised by hand
            stop.set()
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        with start_loopback(cfg, seed=seed, bind_host=bind, at_port=at_port,
                            navdata_port=navdata_port, control_port=control_port,
                            mocap_host=mocap_host, mocap_port=mocap_port) as loop:
            echo(f"simulated AR.Drone 2.0 on {loop.drone_host}: AT commands udp/{loop.at_port}, "
                 f"navdata udp/{loop.navdata_port}"
                 + (f", config tcp/{loop.control_port}" if loop.control_port else ""))
            echo(f"mocap stream: object {loop.object_name!r} at {cfg.sim.mocap_rate_hz:g} Hz "
                 f"→ udp {loop.mocap_host}:{loop.mocap_port}")
            echo(f"seed {seed}; Ctrl-C to stop")
            if cfg.faults.active():  # no experiment clock here: fault times count from now
                loop.set_fault_clock(time.monotonic())
                echo(f"faults {', '.join(cfg.faults.active())}: start_s counted from now")
            try:
                while not stop.wait(0.25):
                    pass
            except KeyboardInterrupt:
                pass
            c = loop.drone.counters
            m = loop.mocap.counters
        echo(f"stopped: {c.at_commands_applied} AT commands, {c.malformed_commands} malformed, "
             f"{c.navdata_packets_out} navdata packets, {m.sent} mocap frames")
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
