"""Whether a bind address is loopback, decided on the addresses it resolves to.

A name is loopback only when it resolves and every address it resolves to is a loopback
address (127.0.0.0/8, ::1, an IPv4-mapped 127.x): ``127.evil.example`` is a name like any
other, and a name that does not resolve is not loopback (the server then asks for a token).
"""

from __future__ import annotations

import ipaddress
import socket


def _ip(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(text.split("%", 1)[0])  # drop an IPv6 zone ("fe80::1%eth0")
    except ValueError:
        return None


def _is_loopback_ip(ip: ipaddress.IPv4Address | ipaddress.IPv6Address) -> bool:
    mapped = getattr(ip, "ipv4_mapped", None)
    return (mapped or ip).is_loopback


def resolved_addresses(host: str) -> list[str]:
    """The addresses ``host`` (a name or an IP literal, IPv6 optionally in brackets) resolves
    to; empty when it does not resolve."""
    host = host.strip()
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not host:
        return []
    if _ip(host) is not None:
        return [host]
    try:
        infos = socket.getaddrinfo(host, None, proto=socket.IPPROTO_TCP)
    except (OSError, UnicodeError):
        return []
    return sorted({str(info[4][0]) for info in infos})


def is_loopback(host: str) -> bool:
    """True when ``host`` resolves and all its addresses are loopback addresses."""
    addrs = [_ip(a) for a in resolved_addresses(host)]
    return bool(addrs) and all(a is not None and _is_loopback_ip(a) for a in addrs)
