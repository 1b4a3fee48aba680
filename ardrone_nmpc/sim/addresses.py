"""Loopback-only addresses: the simulators bind and send to this machine and nowhere else."""

from __future__ import annotations

import ipaddress

__all__ = ["require_loopback_host", "is_loopback_peer"]


def require_loopback_host(host: str, what: str = "address") -> str:
    """``host`` as a numeric IPv4 loopback address (127.0.0.0/8; ``localhost`` → 127.0.0.1).

    Raises ValueError for anything else: the simulators only ever talk to this machine.
    """
    text = str(host).strip()
    if text.lower() == "localhost":
        return "127.0.0.1"
    try:
        addr = ipaddress.ip_address(text)
    except ValueError:
        raise ValueError(f"{what} {host!r} is not a loopback address (use 127.0.0.1)") from None
    if addr.version != 4 or not addr.is_loopback:
        raise ValueError(f"{what} {host!r} is not a loopback address (use 127.0.0.1)")
    return str(addr)


def is_loopback_peer(addr) -> bool:
    """Whether a socket peer ``(ip, port)`` is on this machine."""
    try:
        return ipaddress.ip_address(addr[0]).is_loopback
    except (ValueError, TypeError, IndexError):
        return False
